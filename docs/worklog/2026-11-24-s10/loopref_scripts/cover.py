"""loopref: is the loop's pose covariance (refit on refined tracks) honest? per-axis translation z-scores
against truth, in the LQ colour frame; beside the base fit's (pf.fit.covariance, tidy's).
usage: cover.py OUT.jsonl SESSION..."""
import json, sys
from pathlib import Path
import numpy as np
from align.pipeline import AlignOptions, fit_pair, pair_setup
from align.loop.run import close_loop
from capture.camera import Transform
from capture.session import open_session
from capture.truth import read_truth

out = open(sys.argv[1], "a")
for root in sys.argv[2:]:
    setup = pair_setup(open_session(root), lq="lq", hq="hq")
    T_true = setup.T_lqdepth_lqcolor.inverse() @ Transform.from_list(read_truth(Path(root)).info["T_lq_hq"])
    pf = fit_pair(setup, AlignOptions(progress=False))
    lr = close_loop(setup, pf)
    fl = lr.features
    rec = {"session": root, "refined_fit": lr.refined_fit, "found": fl.accepted(),
           "loop_err_mm": list(1e3 * (fl.T.t - T_true.t)), "loop_sd_mm": list(1e3 * np.sqrt(np.diag(fl.cov)[3:6])),
           "base_err_mm": list(1e3 * (pf.fit.T.t - T_true.t)), "base_sd_mm": list(1e3 * np.sqrt(np.diag(pf.fit.covariance)[3:6])),
           "loop_rot_err_deg": fl.T.error_to(T_true)[1], "loop_rot_sd_deg": float(np.degrees(np.sqrt(np.trace(fl.cov[:3, :3])))),
           "base_rot_sd_deg": pf.fit.rotation_std_deg}
    out.write(json.dumps(rec, default=float) + "\n"); out.flush()
