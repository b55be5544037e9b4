"""tidy2: CPU ms per HQ frame of the footprint-fg rule's warp (EdgeRule.warp) and of the plain warp in the same
run (the ratio is comparable across runs on a loaded machine). usage: fpcpu.py SESSION ALIGNED_DIR"""
import json, sys, time
from pathlib import Path
import numpy as np
from align.reference_edges import EdgeRule
from align.warp import DepthWarper
from capture.camera import Intrinsics, Transform
from capture.session import open_session
sess = open_session(sys.argv[1])
meta = json.loads((Path(sys.argv[2]) / "aligned.json").read_text())
W = DepthWarper(Intrinsics.from_dict(meta["hq_intrinsics"]), Intrinsics.from_dict(meta["lq_intrinsics"]),
                Transform.from_list(meta["T_lq_hq"]), edge_reach=0.0)
rule = EdgeRule.named("footprint-fg")
ids = sess.frames("hq", "depth")["frame_number"].to_numpy()
frames = [sess.read_depth("hq", int(i)) for i in ids[:60:2]]
W(frames[0]); rule.warp(W, frames[0])
t_rule = t_plain = 0.0
for _ in range(3):
    c = time.process_time()
    for f in frames:
        rule.warp(W, f)
    t_rule += time.process_time() - c
    c = time.process_time()
    for f in frames:
        W(f)
    t_plain += time.process_time() - c
n = 3 * len(frames)
print(f"footprint-fg {1e3 * t_rule / n:.2f} ms, plain warp {1e3 * t_plain / n:.2f} ms, ratio {t_rule / t_plain:.3f}")
