"""Per-stage CPU time of the flow reference, as perf/reference_motion.py's throughput runs it.

python kt.py SESSION [--pairs 30] [--rounds 3]
Wraps the compiled passes and the OpenCV steps with timers (process CPU time); prints ms per pair
(best round by total), the plain warp's ms per pair in the same run, and the ratio plain/flow.
"""
import os
os.environ.setdefault("OMP_NUM_THREADS", "1"); os.environ.setdefault("NUMBA_NUM_THREADS", "1")
import sys, time, argparse, collections
import cv2, numpy as np
sys.path.insert(0, os.getcwd())
import perf.reference_motion as rm
import align._flow_kernel as fk
import align.motion_flow as mf
import align.warp as aw
from align.motion import MotionReference
from align.pipeline import pair_setup
from align.reference_edges import EdgeRule
from capture.session import open_session
from capture.truth import read_truth

T = collections.defaultdict(float)
def wrap(mod, name, label=None):
    f = getattr(mod, name)
    lab = label or name
    def g(*a, **k):
        c0 = time.process_time()
        try:
            return f(*a, **k)
        finally:
            T[lab] += time.process_time() - c0
    setattr(mod, name, g)

for n in [x for x in ("scene_shift", "flow_gain", "scene_motion", "block_depths", "fill_offsets", "fill_untrusted",
                     "expand_blocks", "expand_motion", "motion_field") if hasattr(fk, x)]:
    wrap(fk, n)
wrap(mf, "flow_image", "grey"); wrap(mf, "settle_flow", "settle")
_call = mf.ColorFlow.__call__
def dis(self, a, b):
    c0 = time.process_time()
    try:
        return _call(self, a, b)
    finally:
        T["DIS " + ("fast" if self.preset == cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST else "finer")] += time.process_time() - c0
mf.ColorFlow.__call__ = dis
_warp = aw.DepthWarper.warp
def warp(self, depth, *, motion=None):
    c0 = time.process_time()
    try:
        return _warp(self, depth, motion=motion)
    finally:
        T["warp (moved)" if motion is not None else "warp (plain)"] += time.process_time() - c0
aw.DepthWarper.warp = warp

ap = argparse.ArgumentParser(); ap.add_argument("session"); ap.add_argument("--pairs", type=int, default=30)
ap.add_argument("--rounds", type=int, default=3); a = ap.parse_args()
cv2.setNumThreads(1)
sess, tr = open_session(a.session), read_truth(a.session)
setup = pair_setup(sess, lq="lq", hq="hq")
rule = EdgeRule.named("strict")
warper = aw.DepthWarper(setup.K_hq, setup.K_lq, tr.T_lq_hq, edge_reach=rule.edge_reach)
n = min(a.pairs, setup.f_hq.size - 1)
depth = [sess.read_depth("hq", int(setup.f_hq[i])) for i in range(n + 1)]
color = [sess.read_color(setup.hq, int(setup.f_hq_c[setup.hq_color_of_depth[i]])) for i in range(n + 1)]
dt = 0.25 * float(np.median(np.diff(setup.t_hq)))
def ref(kind):
    moved = rm._flow_motion(setup, warper, lambda i: depth[i], lambda i: color[i]) if kind == "flow" else None
    return MotionReference(lambda i: warper(depth[i]), setup.t_hq, enabled=kind != "plain", moved=moved)
for k in ("plain", "flow"):
    ref(k)(0, dt)
best = {}
for r in range(a.rounds):
    for k in ("plain", "flow"):
        T.clear(); R = ref(k); c0 = time.process_time()
        refined = 0
        for i in range(n):
            R(i, dt)
            if k == "flow":
                refined += R._moved.scene_flow.last_refined
        tot = time.process_time() - c0
        if k not in best or tot < best[k][0]:
            best[k] = (tot, dict(T), refined)
pt = best["plain"][0] / n * 1e3; ft, st, refined = best["flow"]; ft = ft / n * 1e3
print(f"plain warp {pt:.2f} ms/pair; flow {ft:.2f} ms/pair; ratio {pt/ft:.3f}; finer flow on {refined}/{n} pairs")
s = 0
for k, v in sorted(st.items(), key=lambda kv: -kv[1]):
    print(f"  {k:16s} {v/n*1e3:6.2f}"); s += v
print(f"  {'rest (python)':16s} {ft - s/n*1e3:6.2f}")
