"""cProfile of 30 consecutive flow pairs (as the throughput harness runs them). python prof.py SESSION"""
import os
os.environ.setdefault("OMP_NUM_THREADS", "1"); os.environ.setdefault("NUMBA_NUM_THREADS", "1")
import sys, cProfile, pstats, time
import cv2, numpy as np
sys.path.insert(0, os.getcwd())
import perf.reference_motion as rm
from align.motion import MotionReference
from align.pipeline import pair_setup
from align.reference_edges import EdgeRule
from align.warp import DepthWarper
from capture.session import open_session
from capture.truth import read_truth
cv2.setNumThreads(1)
sess, tr = open_session(sys.argv[1]), read_truth(sys.argv[1])
setup = pair_setup(sess, lq="lq", hq="hq")
warper = DepthWarper(setup.K_hq, setup.K_lq, tr.T_lq_hq, edge_reach=EdgeRule.named("strict").edge_reach)
n = 30
depth = [sess.read_depth("hq", int(setup.f_hq[i])) for i in range(n + 1)]
color = [sess.read_color(setup.hq, int(setup.f_hq_c[setup.hq_color_of_depth[i]])) for i in range(n + 1)]
dt = 0.25 * float(np.median(np.diff(setup.t_hq)))
def run():
    R = MotionReference(lambda i: warper(depth[i]), setup.t_hq, moved=rm._flow_motion(setup, warper, lambda i: depth[i], lambda i: color[i]))
    for i in range(n):
        R(i, dt)
run()
pr = cProfile.Profile(timer=time.process_time); pr.enable()
for _ in range(3): run()
pr.disable()
pstats.Stats(pr).sort_stats("tottime").print_stats(30)
