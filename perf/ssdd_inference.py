"""SSDD inference time per 640x480 frame through the Denoiser interface, by network width.

    .venv/bin/python perf/ssdd_inference.py [--widths 8,16,32] [--levels 4] [--frames 10] [--threads 2]
        [--prefilter none,bilateral] [--fold-mean] [--motion none,color,depth]

For each width the script writes a weights file of an untrained network of that shape (timing does
not depend on the values), builds ``ssdd_unet`` / ``ssdd_lstm`` from it exactly as ``bench run`` does,
and times ``denoise`` (level 1) and ``denoise_step`` (levels 1 + 2, state carried) on a synthetic
640x480 frame. Reference in the same run: the hole-aware bilateral filter (``bf``) on the same frame.
Prints milliseconds per frame (median, min), the ratio to ``bf``, and the convolutions' multiply-adds
per frame (``GMAC``, counted by a forward hook: independent of the machine's load) with the rate
they ran at (``GMAC/s`` at the median). Nearly all of a frame's time is these convolutions (issue 10
worklog, session 10), so ``GMAC`` over a quiet machine's rate says what a shape can reach. Target (issue 10): < 100 ms at
the default width (16) on two CPU cores. ``--prefilter bilateral`` times level 1 with its bilateral
prefilter (one ``bf`` pass more per frame); ``--fold-mean`` feeds level 2 the mean of the fold models
(``level2.level1_input = "fold_mean"``: k = 2 level-1 passes per frame). ``--motion color`` (or
``depth``) times level 2 with motion (:mod:`methods.ssdd.motion`: one optical flow per frame into the
previous one, the state and the previous output warped); the frames then alternate between the scene
and the scene shifted by 3 pixels, with a textured colour image.
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
from methods.ssdd.config import FOLD_PREFIX, Level1Config, Level2Config, SSDDConfig  # noqa: E402
from methods.ssdd.model import build_level2  # noqa: E402
from methods.ssdd.motion import MotionConfig  # noqa: E402
from methods.ssdd.networks import NetConfig, SSDDUNet  # noqa: E402
from methods.ssdd.prefilter import PrefilterConfig  # noqa: E402
from methods.tools.synthetic import synthetic_scene  # noqa: E402


def _weights(folder: Path, width: int, levels: int, prefilter: str, fold_mean: bool, motion: str = "none") -> Path:
    cfg = SSDDConfig(level1=Level1Config(model=NetConfig(width=width, levels=levels),
                                         prefilter=PrefilterConfig(kind=prefilter)),
                     level2=Level2Config(model=NetConfig(width=width, levels=levels, recurrent=[-1]),
                                         level1_input="fold_mean" if fold_mean else "final",
                                         motion=MotionConfig(kind=motion)))
    torch.manual_seed(0)
    level1 = lambda: SSDDUNet(cfg.level1.model, base=cfg.level1.prefilter.enabled).state_dict()  # noqa: E731
    tensors = {**{f"level1/{k}": v for k, v in level1().items()},
               **{f"level2/{k}": v for k, v in build_level2(cfg.level2).state_dict().items()}}
    if fold_mean:
        tensors.update({f"{FOLD_PREFIX}{f}/{k}": v for f in range(cfg.folds) for k, v in level1().items()})
    path = folder / f"w{width}-{prefilter}-{motion}.safetensors"
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


def _gmac(fn) -> float:
    """Multiply-adds (10^9) of the ``Conv2d`` modules that one call of ``fn`` runs."""
    count = [0]

    def hook(module, inputs, output):
        if isinstance(module, torch.nn.Conv2d):
            k = module.weight.shape[1] * module.weight.shape[2] * module.weight.shape[3]
            count[0] += output.numel() * k

    handle = torch.nn.modules.module.register_module_forward_hook(hook)
    try:
        fn()
    finally:
        handle.remove()
    return count[0] / 1e9


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--widths", default="8,16,32")
    ap.add_argument("--levels", type=int, default=4)
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--prefilter", default="none", help="comma list of level-1 prefilters to time (none, bilateral)")
    ap.add_argument("--fold-mean", action="store_true", help="level 2 fed the mean of the 2 fold models")
    ap.add_argument("--motion", default="none", help="comma list of level-2 motion kinds to time (none, color, depth)")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    _, depth = synthetic_scene((480, 640), seed=1)
    color = np.random.default_rng(0).integers(0, 256, (480, 640, 3)).astype(np.uint8)
    frames = [FrameInput(0, depth, color=color), FrameInput(1, np.roll(depth, 3, axis=1), color=np.roll(color, 3, axis=1))]
    bf = get("bf")
    ref = _time(lambda: bf.denoise(depth), a.frames)
    print(f"640x480, {a.threads} torch threads, {a.frames} frames; reference bf: median {np.median(ref):.1f} ms")
    print(f"{'width':>5} {'levels':>6} {'prefilter':>9} {'motion':>6} {'method':>10} {'median ms':>10} {'min ms':>8} "
          f"{'x bf':>6} {'GMAC':>6} {'GMAC/s':>7}")
    with tempfile.TemporaryDirectory() as tmp:
        for width, pre, mo in ((int(w), p, m) for w in a.widths.split(",") for p in a.prefilter.split(",")
                               for m in a.motion.split(",")):
            path = _weights(Path(tmp), width, a.levels, pre, a.fold_mean, mo)
            unet = get("ssdd_unet", weights=str(path))
            lstm = get("ssdd_lstm", weights=str(path))
            state = {"s": lstm.start_sequence(), "n": 0}

            def step():
                state["n"] += 1
                _, state["s"] = lstm.denoise_step(frames[state["n"] % 2], state["s"])

            todo = (("ssdd_lstm", step),) if mo != "none" and len(a.motion.split(",")) > 1 else \
                (("ssdd_unet", lambda: unet.denoise(depth)), ("ssdd_lstm", step))
            for name, fn in todo:
                t = _time(fn, a.frames)
                g = _gmac(fn)
                print(f"{width:>5} {a.levels:>6} {pre:>9} {mo:>6} {name:>10} {np.median(t):>10.1f} {min(t):>8.1f} "
                      f"{np.median(t) / np.median(ref):>6.2f} {g:>6.2f} {g / np.median(t) * 1000:>7.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
