"""Where a 640x480 ssdd_unet frame's time goes besides the net (2 threads; run under chrt -f 1): min ms of each part."""
import sys, time, tempfile
from pathlib import Path
import numpy as np, torch
sys.path.insert(0, "perf")
import ssdd_inference as P
from methods.ssdd.model import level1_depth, _code
from methods.nn.normalize import encode_depth, frame_centre
from methods.ssdd.prefilter import prefilter_frames
from methods.base import FrameInput
from methods.tools.synthetic import synthetic_scene
torch.set_num_threads(2)
width, levels, rounds = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
_, depth = synthetic_scene((480, 640), seed=1)
f = FrameInput(0, depth)
with tempfile.TemporaryDirectory() as tmp:
    path = P._weights(Path(tmp), width, levels, "bilateral", True)
    u, _ = P._methods(path, "on")
    net, data, cfg = u.runtime["level1"], u.config.level1.data, u.config.level1
    d, rgb, base = u._tensors([f])
    x, valid, centre = encode_depth(d, **_code(data))
    xb = encode_depth(base, centre=centre, **_code(data))[0]
    parts = {
        "denoise (all)": lambda: u.denoise(depth),
        "prefilter": lambda: prefilter_frames([depth], cfg.prefilter),
        "_tensors (incl. prefilter)": lambda: u._tensors([f]),
        "frame_centre (nanmedian)": lambda: frame_centre(d),
        "encode x2": lambda: (encode_depth(d, **_code(data)), encode_depth(base, centre=centre, **_code(data))),
        "net": lambda: net(x, valid, None, None, xb),
        "level1_depth": lambda: level1_depth(net, d, rgb, data, base),
        "_finish": lambda: u._finish(d[0, 0], depth),
    }
    with torch.inference_mode():
        t = P._time_modes(parts, rounds)
for k, v in t.items():
    print(f"w{width}/{levels} {k:>28}: min {min(v):6.1f} med {np.median(v):6.1f} ms")
    xr = torch.randn_like(x); vr = (torch.rand_like(x) > 0.1).float(); br = xr + 0.01 * torch.randn_like(xr)
    more = {"net (real inputs)": lambda: net(x, valid, None, None, xb), "net (random inputs)": lambda: net(xr, vr, None, None, br)}
    with torch.inference_mode():
        t = P._time_modes(more, rounds)
        for k, v in t.items():
            print(f"w{width}/{levels} {k:>28}: min {min(v):6.1f} med {np.median(v):6.1f} ms")
        torch.set_flush_denormal(True)
        t = P._time_modes(more, rounds)
        for k, v in t.items():
            print(f"w{width}/{levels} {k + ' FTZ':>28}: min {min(v):6.1f} med {np.median(v):6.1f} ms")
