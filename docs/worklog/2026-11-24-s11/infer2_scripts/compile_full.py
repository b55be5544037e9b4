"""ssdd_unet / ssdd_lstm through the Denoiser at 640x480 with torch.compile'd level-1 nets (lanes off, 2 threads) vs
the landed path (lanes off and on), alternating call by call. Run under chrt -f 1; compile time printed."""
import sys, time, tempfile
from pathlib import Path
import numpy as np, torch
sys.path.insert(0, "perf")
import ssdd_inference as P
from methods.base import FrameInput
from methods.tools.synthetic import synthetic_scene
width, levels, rounds = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
torch.set_num_threads(2)
_, depth = synthetic_scene((480, 640), seed=1)
frames = [FrameInput(0, depth), FrameInput(1, np.roll(depth, 3, axis=1))]
with tempfile.TemporaryDirectory() as tmp:
    path = P._weights(Path(tmp), width, levels, "bilateral", True)
    plain = P._callables(*P._methods(path, "off"), depth, frames, 1)
    laned = P._callables(*P._methods(path, "on"), depth, frames, 1)
    cu, cl = P._methods(path, "off")
    cu.runtime["level1"] = torch.compile(cu.runtime["level1"])
    cl.runtime["feeders"] = [torch.compile(n) for n in cl.runtime["feeders"]]
    comp = P._callables(cu, cl, depth, frames, 1)
    t0 = time.perf_counter(); comp["ssdd_unet"][0](); comp["ssdd_lstm"][0](); print(f"compile {time.perf_counter() - t0:.1f} s")
    ref, got = P._methods(path, "off")[0].denoise(depth), cu.denoise(depth)
    print("unet max|diff| compiled vs plain", float(np.nanmax(np.abs(ref - got))))
    for name in ("ssdd_unet", "ssdd_lstm"):
        t = P._time_modes({"plain": plain[name][0], "lanes": laned[name][0], "compiled": comp[name][0]}, rounds)
        for k, v in t.items():
            print(f"w{width}/{levels} {name} {k:>8}: med {np.median(v):7.1f} min {min(v):7.1f}  plain/this med {np.median(t['plain'])/np.median(v):.2f} min {min(t['plain'])/min(v):.2f}")
