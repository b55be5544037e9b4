"""SSDD inference time per 640x480 frame through the Denoiser interface, by network width.

    .venv/bin/python perf/ssdd_inference.py [--widths 8,16,32] [--levels 4] [--frames 10] [--threads 2]

For each width the script writes a weights file of an untrained network of that shape (timing does
not depend on the values), builds ``ssdd_unet`` / ``ssdd_lstm`` from it exactly as ``bench run`` does,
and times ``denoise`` (level 1) and ``denoise_step`` (levels 1 + 2, state carried) on a synthetic
640x480 frame. Reference in the same run: the hole-aware bilateral filter (``bf``) on the same frame.
Prints milliseconds per frame (median, min) and the ratio to ``bf``. Target (issue 10): < 100 ms at
the default width (16) on two CPU cores.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from methods import get  # noqa: E402
from methods.base import FrameInput  # noqa: E402
from methods.nn.checkpoint import save_tensors  # noqa: E402
from methods.nn.config import to_dict  # noqa: E402
from methods.ssdd.config import Level1Config, Level2Config, SSDDConfig  # noqa: E402
from methods.ssdd.networks import NetConfig, SSDDLSTMUNet, SSDDUNet  # noqa: E402
from methods.tools.synthetic import synthetic_scene  # noqa: E402


def _weights(folder: Path, width: int, levels: int) -> Path:
    cfg = SSDDConfig(level1=Level1Config(model=NetConfig(width=width, levels=levels)),
                     level2=Level2Config(model=NetConfig(width=width, levels=levels, recurrent=[-1])))
    torch.manual_seed(0)
    tensors = {**{f"level1/{k}": v for k, v in SSDDUNet(cfg.level1.model).state_dict().items()},
               **{f"level2/{k}": v for k, v in SSDDLSTMUNet(cfg.level2.model).state_dict().items()}}
    path = folder / f"w{width}.safetensors"
    save_tensors(path, tensors, kind="weights", meta={"method": "ssdd_lstm", "config": to_dict(cfg),
                                                       "training": {"datasets": []}})
    return path


def _time(fn, frames: int) -> list[float]:
    fn()                                   # warm-up (allocations, oneDNN kernels)
    out = []
    for _ in range(frames):
        t0 = time.perf_counter()
        fn()
        out.append((time.perf_counter() - t0) * 1000)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--widths", default="8,16,32")
    ap.add_argument("--levels", type=int, default=4)
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    _, depth = synthetic_scene((480, 640), seed=1)
    bf = get("bf")
    ref = _time(lambda: bf.denoise(depth), a.frames)
    print(f"640x480, {a.threads} torch threads, {a.frames} frames; reference bf: median {np.median(ref):.1f} ms")
    print(f"{'width':>5} {'levels':>6} {'method':>10} {'median ms':>10} {'min ms':>8} {'x bf':>6}")
    with tempfile.TemporaryDirectory() as tmp:
        for width in (int(w) for w in a.widths.split(",")):
            path = _weights(Path(tmp), width, a.levels)
            unet = get("ssdd_unet", weights=str(path))
            lstm = get("ssdd_lstm", weights=str(path))
            state = {"s": lstm.start_sequence()}

            def step():
                _, state["s"] = lstm.denoise_step(FrameInput(0, depth), state["s"])

            for name, fn in (("ssdd_unet", lambda: unet.denoise(depth)), ("ssdd_lstm", step)):
                t = _time(fn, a.frames)
                print(f"{width:>5} {a.levels:>6} {name:>10} {np.median(t):>10.1f} {min(t):>8.1f} "
                      f"{np.median(t) / np.median(ref):>6.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
