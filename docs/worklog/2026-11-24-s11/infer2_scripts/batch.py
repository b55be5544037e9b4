"""ssdd_unet on 4 frames at 640x480, 2 threads: one batch of 4 (lanes off), 2 lanes of 2, 4 single frames one after
another, 4 single frames on 2 lanes. ms per frame, alternating call by call. Run under chrt -f 1 for quiet cores."""
import sys, time, tempfile
from pathlib import Path
import numpy as np, torch
sys.path.insert(0, "perf")
import ssdd_inference as P
from methods.base import FrameInput
from methods.nn.lanes import Lanes
from methods.tools.synthetic import synthetic_scene
width, levels, rounds = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
torch.set_num_threads(2)
_, depth = synthetic_scene((480, 640), seed=1)
frames = [FrameInput(i, np.roll(depth, 3 * i, axis=1)) for i in range(4)]
with tempfile.TemporaryDirectory() as tmp:
    path = P._weights(Path(tmp), width, levels, "bilateral", True)
    off, _ = P._methods(path, "off"); on, _ = P._methods(path, "on")
    lanes = Lanes(2, 1)
    fns = {"batch4": lambda: off.denoise_batch(frames), "lanes2x2": lambda: on.denoise_batch(frames),
           "singles": lambda: [off.denoise_batch([f]) for f in frames],
           "lanes_singles": lambda: lanes.map(lambda f: off.denoise_batch([f]), frames)}
    ref = fns["batch4"]()
    for k, f in fns.items():
        o = f(); o = [x[0] if isinstance(x, list) else x for x in o]
        print(k, "max|diff| vs batch4", max(float(np.nanmax(np.abs(a - b))) for a, b in zip(ref, o)))
    t = P._time_modes(fns, rounds)
for k, v in t.items():
    v = np.array(v) / 4
    print(f"w{width}/{levels} {k:>14} ms/frame median {np.median(v):7.1f} min {v.min():7.1f}  batch4/this med {np.median(np.array(t['batch4'])/4)/np.median(v):.2f} min {np.min(t['batch4'])/4/v.min():.2f}")
