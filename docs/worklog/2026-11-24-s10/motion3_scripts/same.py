"""Dump the flow references of 30 consecutive pairs (throughput setting) to an npz, or compare two dumps.
python same.py SESSION OUT.npz  |  python same.py --cmp A.npz B.npz"""
import os, sys
os.environ.setdefault("NUMBA_NUM_THREADS", "1")
import numpy as np
if sys.argv[1] == "--cmp":
    a, b = np.load(sys.argv[2]), np.load(sys.argv[3])
    for k in a.files:
        x, y = a[k], b[k]
        same = np.array_equal(x, y, equal_nan=True)
        fin = np.isfinite(x) & np.isfinite(y)
        print(k, "identical" if same else f"differ: nan pattern {int((np.isfinite(x) != np.isfinite(y)).sum())} px, "
              f"max |diff| {np.abs(x - y)[fin].max():.3g} m, px differing {int((x[fin] != y[fin]).sum())}")
    sys.exit()
import cv2
sys.path.insert(0, os.getcwd())
import perf.reference_motion as rm
from align.motion import MotionReference
from align.pipeline import pair_setup
from align.reference_edges import EdgeRule
from align.warp import DepthWarper
from capture.session import open_session
from capture.truth import read_truth
sess, tr = open_session(sys.argv[1]), read_truth(sys.argv[1])
setup = pair_setup(sess, lq="lq", hq="hq")
warper = DepthWarper(setup.K_hq, setup.K_lq, tr.T_lq_hq, edge_reach=EdgeRule.named("strict").edge_reach)
n = 30
depth = [sess.read_depth("hq", int(setup.f_hq[i])) for i in range(n + 1)]
color = [sess.read_color(setup.hq, int(setup.f_hq_c[setup.hq_color_of_depth[i]])) for i in range(n + 1)]
dt = 0.25 * float(np.median(np.diff(setup.t_hq)))
R = MotionReference(lambda i: warper(depth[i]), setup.t_hq, moved=rm._flow_motion(setup, warper, lambda i: depth[i], lambda i: color[i]))
np.savez(sys.argv[2], **{f"p{i}": R(i, dt)[0] for i in range(n)})
