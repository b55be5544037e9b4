import os, sys, time
os.environ["OMP_NUM_THREADS"] = "1"
import cv2, numpy as np
cv2.setNumThreads(1)
sys.path.insert(0, os.getcwd())
from capture.session import open_session
from align.pipeline import pair_setup
from align.motion_flow import flow_image
sess = open_session("/tmp/recheck/m/p7_s12"); setup = pair_setup(sess, lq="lq", hq="hq")
g = [flow_image(sess.read_color(setup.hq, int(setup.f_hq_c[setup.hq_color_of_depth[i]])), scale=0.25) for i in range(20, 31)]
print(g[0].shape)
P = cv2
cfgs = {"uf f1": (P.DISOPTICAL_FLOW_PRESET_ULTRAFAST, 1, None), "uf f0": (P.DISOPTICAL_FLOW_PRESET_ULTRAFAST, 0, None),
        "fast f0 r0": (P.DISOPTICAL_FLOW_PRESET_FAST, 0, 0), "fast f1 r0": (P.DISOPTICAL_FLOW_PRESET_FAST, 1, 0),
        "med f0 r0": (P.DISOPTICAL_FLOW_PRESET_MEDIUM, 0, 0), "med f1 r0": (P.DISOPTICAL_FLOW_PRESET_MEDIUM, 1, 0)}
for name, (p, f, r) in cfgs.items():
    d = cv2.DISOpticalFlow_create(p); d.setFinestScale(f)
    if r is not None: d.setVariationalRefinementIterations(r)
    best = 1e9
    for rep in range(3):
        t = time.process_time()
        for i in range(10): d.calc(g[i], g[i + 1], None)
        best = min(best, (time.process_time() - t) / 10)
    print(f"{name}: {best * 1000:.2f} ms; patch {d.getPatchSize()} stride {d.getPatchStride()} gd {d.getGradientDescentIterations()}")
