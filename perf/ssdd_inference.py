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

``--lanes off,on`` times each method with inference lanes off (every pass one after another on all threads)
and on (:mod:`methods.nn.lanes`: the fold models of the fold mean, the frames of a batch, side by side, one
thread each), the two alternating frame by frame in the same run, and prints ``x off``: the median time with
lanes off over this row's (a speed-up above 1; ``min x`` the same for the minima). ``--batch 4`` adds the row
``ssdd_unet/4``: milliseconds per frame of ``denoise_batch`` on 4 frames (how ``bench run`` feeds it; on the
CPU its frames run one at a time, side by side with lanes on). ``--lanes off,compile`` adds the level-1 nets
compiled by ``torch.compile`` (:mod:`methods.nn.compiled`; the compilation happens in the warm-up call, which is
not timed). Timings on a machine shared with other jobs
vary 2-4x; ``chrt -f 1`` in front of the command gives the run the cores (issue 10 worklog, session 11).
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from unittest import mock

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from methods import get  # noqa: E402
from methods.base import FrameInput  # noqa: E402
from methods.nn.checkpoint import save_tensors  # noqa: E402
from methods.nn.compiled import ENV as COMPILE_ENV  # noqa: E402
from methods.nn.lanes import ENV as LANES_ENV  # noqa: E402
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
    return _time_modes({"": fn}, frames)[""]


def _time_modes(fns: dict, frames: int) -> dict[str, list[float]]:
    """Milliseconds of each call of each function, the functions alternating call by call (one warm-up each)."""
    for fn in fns.values():
        fn()                               # warm-up (allocations, oneDNN kernels)
    out: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(frames):
        for k, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            out[k].append((time.perf_counter() - t0) * 1000)
    return out


def _methods(path: Path, lanes: str):
    """``ssdd_unet`` and ``ssdd_lstm`` on ``path``, prepared with inference lanes ``"on"`` or ``"off"``, or with
    ``"compile"``: the level-1 nets compiled (``DEPTHBENCH_COMPILE=1``, lanes off; compiled at the warm-up call)."""
    env = {LANES_ENV: "1" if lanes == "on" else "0", COMPILE_ENV: "1" if lanes == "compile" else "0"}
    with mock.patch.dict(os.environ, env):   # read when the methods prepare (methods.ssdd.denoise)
        unet, lstm = get("ssdd_unet", weights=str(path)), get("ssdd_lstm", weights=str(path))
        unet.ensure_prepared()
        lstm.ensure_prepared()
    return unet, lstm


def _callables(unet, lstm, depth, frames: list, batch: int) -> dict:
    """name -> (function of one timed call, frames it denoises)."""
    state = {"s": lstm.start_sequence(), "n": 0}

    def step():
        state["n"] += 1
        _, state["s"] = lstm.denoise_step(frames[state["n"] % 2], state["s"])

    out = {"ssdd_unet": (lambda: unet.denoise(depth), 1), "ssdd_lstm": (step, 1)}
    if batch > 1:
        out[f"ssdd_unet/{batch}"] = (lambda: unet.denoise_batch([frames[i % 2] for i in range(batch)]), batch)
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


def _rows(a, path: Path, width: int, pre: str, mo: str, depth, frames: list) -> None:
    """Print one row per method and lanes mode of one weights file."""
    modes = a.lanes.split(",")
    per_mode = {m: _callables(*_methods(path, m), depth, frames, a.batch) for m in modes}
    names = list(per_mode[modes[0]])
    if mo != "none" and len(a.motion.split(",")) > 1:
        names = ["ssdd_lstm"]
    for name in names:
        n = per_mode[modes[0]][name][1]
        t = {m: np.array(v) / n for m, v in _time_modes({m: per_mode[m][name][0] for m in modes}, a.frames).items()}
        g = _gmac(per_mode[modes[0]][name][0]) / n
        for m in modes:
            ref = t.get("off", t[m])
            print(f"{width:>5} {a.levels:>6} {pre:>9} {mo:>6} {name:>11} {m:>5} {np.median(t[m]):>10.1f} "
                  f"{t[m].min():>8.1f} {np.median(t[m]) / a.bf_ms:>6.2f} {np.median(ref) / np.median(t[m]):>6.2f} "
                  f"{ref.min() / t[m].min():>6.2f} {g:>6.2f} {g / np.median(t[m]) * 1000:>7.1f}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--widths", default="8,16,32")
    ap.add_argument("--levels", type=int, default=4)
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--prefilter", default="none", help="comma list of level-1 prefilters to time (none, bilateral)")
    ap.add_argument("--fold-mean", action="store_true", help="level 2 fed the mean of the 2 fold models")
    ap.add_argument("--motion", default="none", help="comma list of level-2 motion kinds to time (none, color, depth)")
    ap.add_argument("--lanes", default="on", help="comma list of inference modes to time, alternating (on, off, compile)")
    ap.add_argument("--batch", type=int, default=1, help="also time ssdd_unet's denoise_batch on this many frames")
    a = ap.parse_args()
    if not set(a.lanes.split(",")) <= {"on", "off", "compile"}:
        ap.error(f"--lanes: a comma list of on, off, compile; got {a.lanes!r}")
    torch.set_num_threads(a.threads)
    _, depth = synthetic_scene((480, 640), seed=1)
    color = np.random.default_rng(0).integers(0, 256, (480, 640, 3)).astype(np.uint8)
    frames = [FrameInput(0, depth, color=color), FrameInput(1, np.roll(depth, 3, axis=1), color=np.roll(color, 3, axis=1))]
    bf = get("bf")
    a.bf_ms = float(np.median(_time(lambda: bf.denoise(depth), a.frames)))
    print(f"640x480, {a.threads} torch threads, {a.frames} frames; reference bf: median {a.bf_ms:.1f} ms")
    print(f"{'width':>5} {'levels':>6} {'prefilter':>9} {'motion':>6} {'method':>11} {'lanes':>5} {'median ms':>10} "
          f"{'min ms':>8} {'x bf':>6} {'x off':>6} {'min x':>6} {'GMAC':>6} {'GMAC/s':>7}")
    with tempfile.TemporaryDirectory() as tmp:
        for width, pre, mo in ((int(w), p, m) for w in a.widths.split(",") for p in a.prefilter.split(",")
                               for m in a.motion.split(",")):
            _rows(a, _weights(Path(tmp), width, a.levels, pre, a.fold_mean, mo), width, pre, mo, depth, frames)
    return 0


if __name__ == "__main__":
    sys.exit(main())
