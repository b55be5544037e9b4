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
U = cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST
for stride, gd, sp in ((4, 12, 1), (5, 12, 1), (6, 12, 1), (4, 8, 1), (5, 8, 1), (4, 6, 1), (4, 12, 0)):
    d = cv2.DISOpticalFlow_create(U); d.setFinestScale(0); d.setPatchStride(stride); d.setGradientDescentIterations(gd); d.setUseSpatialPropagation(bool(sp))
    best = 1e9
    for rep in range(3):
        t = time.process_time()
        for i in range(10): d.calc(g[i], g[i + 1], None)
        best = min(best, (time.process_time() - t) / 10)
    print(f"uf f0 stride {stride} gd {gd} sp {sp}: {best * 1000:.2f} ms")
