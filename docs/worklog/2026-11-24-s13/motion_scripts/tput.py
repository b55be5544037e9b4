"""Throughput (pairs/s by CPU time, best of 3, taking turns) of the plain warp and of the flow reference with
several primary flows, in one run: perf/reference_motion.py's _throughput with more kinds.
python tput.py SESSION FRAMES"""
import os, sys, time
os.environ.setdefault("OMP_NUM_THREADS", "1"); os.environ.setdefault("NUMBA_NUM_THREADS", "1")
import numpy as np, cv2
sys.path.insert(0, os.getcwd())
import perf.reference_motion as rm
import align.motion_flow as mf
from align.motion import MotionReference
from align.reference_edges import EdgeRule
cv2.setNumThreads(1)
root, n = sys.argv[1], int(sys.argv[2])
setup, warper, tr, pairs = rm._pairs(root, 1, EdgeRule.named("strict"))
sess = setup.session
n = min(n, setup.f_hq.size - 1)
depth = [sess.read_depth("hq", int(setup.f_hq[i])) for i in range(n + 1)]
color = [sess.read_color(setup.hq, int(setup.f_hq_c[setup.hq_color_of_depth[i]])) for i in range(n + 1)]
dt = 0.25 * float(np.median(np.diff(setup.t_hq)))
U, M = cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST, cv2.DISOPTICAL_FLOW_PRESET_MEDIUM
CFG = {"flow before (level 1)": (U, 1, None, 4), "flow after (default)": None}
def reference(k):
    if k == "plain":
        return MotionReference(lambda i: warper(depth[i]), setup.t_hq, enabled=False)
    fm = rm._flow_motion(setup, warper, lambda i: depth[i], lambda i: color[i])
    if CFG[k] is not None:
        fm._flow = mf.ColorFlow(CFG[k][0], finest=CFG[k][1], refinement=CFG[k][2], patch_stride=CFG[k][3])
    return MotionReference(lambda i: warper(depth[i]), setup.t_hq, moved=fm)
kinds = ["plain", *CFG]
for k in kinds:
    reference(k)(0, dt)
cpu = {k: [] for k in kinds}
for _ in range(3):
    for k in kinds:
        ref = reference(k); c0 = time.process_time()
        for i in range(n):
            ref(i, dt)
        cpu[k].append(n / (time.process_time() - c0))
for k in kinds:
    print(f"{k:20s} {max(cpu[k]):6.1f} pairs/s (CPU), ratio to plain {max(cpu[k]) / max(cpu['plain']):.3f}")
