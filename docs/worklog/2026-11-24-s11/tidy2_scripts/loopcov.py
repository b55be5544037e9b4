"""tidy2: the effect loop's pose covariance against truth. Per session: fit_pair + close_loop (defaults), then
the loop's final pose error (rotation vector, translation of T_lqcolor_hqdepth; truth from the simulator), its
cluster-robust covariance over (pose, shift), and the shift gain g = Sigma[:, s] / Sigma[s, s] of the final fit's
Gauss-Newton information (how the parameters move with the shift when the rest are refitted).
usage: loopcov.py OUT.jsonl SESSION..."""
import json, sys, time
from pathlib import Path
import numpy as np
from align.pipeline import AlignOptions, fit_pair, pair_setup
from align.loop.run import close_loop
from align.loop.loop import _cols, _irls_parts
from capture.camera import Transform
from capture.session import open_session
from capture.truth import read_truth

out = open(sys.argv[1], "a")
for root in sys.argv[2:]:
    c0 = time.process_time()
    setup = pair_setup(open_session(root), lq="lq", hq="hq")
    info = read_truth(Path(root)).info
    T_true = setup.T_lqdepth_lqcolor.inverse() @ Transform.from_list(info["T_lq_hq"])
    pf = fit_pair(setup, AlignOptions(progress=False))
    lr = close_loop(setup, pf)
    fl = lr.features
    m = fl.model
    free = _cols(m, fl.accepted())
    r = m.residuals(fl.x)
    c = float(max(0.1, 2.5 * 1.4826 * np.median(np.abs(r[r != 0]))))
    A_inv, _ = _irls_parts(m.jacobian(fl.x, columns=free), r, c)
    gain = A_inv[:, 6] / A_inv[6, 6]
    p_fit = np.concatenate([fl.T.rotvec(), fl.T.t])
    p_true = np.concatenate([T_true.rotvec(), T_true.t])
    p_base = np.concatenate([pf.fit.T.rotvec(), pf.fit.T.t])
    rec = {"session": root, "refined_fit": lr.refined_fit, "found": fl.accepted(), "changed": lr.changed_geometry,
           "err": list(p_fit - p_true), "cov": fl.cov[:7, :7].tolist(), "gain": list(gain[:7]),
           "shift_us": fl.shift_us, "shift_true_us": info.get("time_shift_us"),
           "base_err": list(p_base - p_true), "base_cov": pf.fit.covariance.tolist(),
           "cov_shared": None if getattr(fl, "cov_shared", None) is None else fl.cov_shared[:7, :7].tolist(),
           "A_inv": A_inv.tolist(), "names": [m.names()[i] for i in free],
           "model_err": [float(v) for n in fl.accepted() for e in fl.model.effects if e.name == n for v in e.model_errors(m.data)],
           "cpu_s": time.process_time() - c0}
    out.write(json.dumps(rec, default=float) + "\n"); out.flush()
    print(root, rec["found"], rec["cpu_s"], flush=True)
