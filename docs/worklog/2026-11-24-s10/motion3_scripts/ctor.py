import os, sys, time
sys.path.insert(0, os.getcwd())
import numpy as np
from align.pipeline import pair_setup
from align.motion_flow import SceneFlow
from capture.session import open_session
sess = open_session(sys.argv[1]); setup = pair_setup(sess, lq="lq", hq="hq")
K = setup.K_hq; T = setup.T_hqdepth_hqcolor.inverse()
print("depth distortion", K.has_distortion, "colour distortion", setup.K_hq_color.has_distortion, K.shape)
for f, name in ((lambda: K.ray_grid(), "ray_grid"), (lambda: SceneFlow(setup.K_hq, setup.K_hq_color, T), "SceneFlow()")):
    t = []
    for _ in range(5):
        c = time.process_time(); f(); t.append(time.process_time() - c)
    print(name, f"{min(t)*1e3:.2f} ms")
rays = K.ray_grid().astype(np.float32)
t = []
for _ in range(5):
    c = time.process_time(); np.einsum("ij,hwj->ihw", T.R, rays); t.append(time.process_time() - c)
print("einsum", f"{min(t)*1e3:.2f} ms")
