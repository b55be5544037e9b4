"""loopref: the loop's final T_lq_hq with/without the refit on refined tracks, against truth.
usage: measure.py OUT.jsonl SESSION [SESSION...]   (sessions simulated beforehand)"""
import json, sys, time
from pathlib import Path
import numpy as np
from align.pipeline import AlignOptions, fit_pair, pair_setup
from align.loop.run import close_loop
from capture.camera import Transform
from capture.session import open_session
from capture.truth import read_truth

out = open(sys.argv[1], "a")
for root in sys.argv[2:]:
    sess = open_session(root)
    tr = read_truth(Path(root))
    T_true = Transform.from_list(tr.info["T_lq_hq"])
    setup = pair_setup(sess, lq="lq", hq="hq")
    opts = AlignOptions(progress=False)
    pf = fit_pair(setup, opts)
    rec = {"session": root, "truth_effects": tr.info.get("effects"),
           "base": list(pf.T_lq_hq.t - T_true.t) + [pf.T_lq_hq.error_to(T_true)[1]]}
    for refine in (False, True):
        c0 = time.process_time()
        lr = close_loop(setup, pf, refine=refine)
        T = lr.T_lq_hq
        rec["refine" if refine else "sift"] = {
            "err": list((T.t - T_true.t) * 1000) + [T.error_to(T_true)[1]],
            "found": [f.name for f in lr.findings if f.source == "found"],
            "params": {f.name: (f.params, f.std) for f in lr.findings if f.source == "found"},
            "shift_us": lr.shift_us, "drift_ppm": lr.drift_ppm, "refined_fit": lr.refined_fit,
            "cpu_s": time.process_time() - c0}
    rec["base"] = [v * 1000 for v in rec["base"][:3]] + rec["base"][3:]
    out.write(json.dumps(rec, default=float) + "\n"); out.flush()
    print(json.dumps(rec, default=float))
