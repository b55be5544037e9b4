"""How much of the fit's error is the time shift's: refit the final correspondences at the true shift and at +-1 ms.
python extr_shift.py SEED...   (sessions from extr_cov.py in /tmp/tidy_extr)"""
import sys
from pathlib import Path
import numpy as np
import align.pipeline as P
from capture.session import open_session
from capture.truth import read_truth

losses = []
Orig = P.ShiftLoss
class Rec(Orig):
    def __init__(self, *a, **k):
        super().__init__(*a, **k); losses.append(self)
P.ShiftLoss = Rec
for seed in map(int, sys.argv[1:]):
    root = Path(f"/tmp/tidy_extr/s{seed}")
    sess = open_session(root)
    setup = P.pair_setup(sess, lq=sess.sensors_with_role("lq")[0], hq=sess.sensors_with_role("hq")[0])
    losses.clear()
    pf = P.fit_pair(setup, P.AlignOptions(progress=False, workers=1))
    loss, sh = losses[-1], pf.shift
    tr = read_truth(root)
    T_true = setup.T_lqdepth_lqcolor.inverse() @ tr.T_lq_hq
    def refit(delta_us):
        pos, _ = loss.lq_positions(delta_us, sh.drift_ppm * 1e-6)
        ok = np.all(np.isfinite(pos), 1)
        return P.fit_extrinsics(loss.points[ok], pos[ok], setup.K_lq_color, T_init=pf.fit.T).T
    at_true = refit(float(tr.time_shift_us))
    plus, minus = refit(sh.time_shift_us + 1000), refit(sh.time_shift_us - 1000)
    print(seed, f"shift err {sh.time_shift_us - tr.time_shift_us:+.0f} us (sd {sh.std_us:.0f})",
          "T err mm", np.round((pf.fit.T.t - T_true.t) * 1e3, 2),
          "at true shift", np.round((at_true.t - T_true.t) * 1e3, 2),
          "dT/dshift mm/ms", np.round((plus.t - minus.t) / 2 * 1e3, 2), flush=True)
