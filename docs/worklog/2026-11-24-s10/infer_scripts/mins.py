"""Min wall ms over R interleaved rounds: ssdd_unet.denoise vs its parts, ssdd_lstm step vs its parts (w8, bilateral, fold_mean)."""
import sys, tempfile, time
from pathlib import Path
import numpy as np, torch
sys.path.insert(0, "perf")
import ssdd_inference as P
from methods import get
from methods.base import FrameInput
from methods.tools.synthetic import synthetic_scene
from methods.ssdd.model import level1_depth
torch.set_num_threads(2)
R = int(sys.argv[1]) if len(sys.argv) > 1 else 25
_, depth = synthetic_scene((480, 640), seed=1)
frames = [FrameInput(0, depth), FrameInput(1, np.roll(depth, 3, axis=1))]
with tempfile.TemporaryDirectory() as tmp:
    path = P._weights(Path(tmp), 8, 4, "bilateral", True)
    lstm = get("ssdd_lstm", weights=str(path)); unet = get("ssdd_unet", weights=str(path))
    unet.denoise(depth)
    st = {"s": lstm.denoise_step(frames[0], None)[1], "n": 0}
    def step():
        st["n"] += 1; _, st["s"] = lstm.denoise_step(frames[st["n"] % 2], st["s"])
    d, rgb, base = unet._tensors([frames[0]]); cfg = unet.config
    def l1():
        with torch.inference_mode():
            level1_depth(unet.runtime["level1"], d, rgb, cfg.level1.data, base)
    parts = {"bf": lambda: get("bf").denoise(depth), "ssdd_unet.denoise": lambda: unet.denoise(depth),
             "  _tensors (prefilter)": lambda: unet._tensors([frames[0]]), "  level1_depth": l1,
             "ssdd_lstm step": step}
    res = {k: [] for k in parts}
    for _ in range(R):
        for k, f in parts.items():
            t0 = time.perf_counter(); f(); res[k].append((time.perf_counter() - t0) * 1000)
    for k, v in res.items():
        print(f"{k:>24}: min {min(v):7.1f}  p10 {np.percentile(v, 10):7.1f}  median {np.median(v):7.1f} ms")
