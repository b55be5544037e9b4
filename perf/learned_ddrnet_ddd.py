"""Timings of DDRNet and DDD on the CPU: inference per 640x480 frame, training samples per second.

    .venv/bin/python perf/learned_ddrnet_ddd.py [--threads 2] [--repeats 5] [--device cpu|cuda]

Inference runs the networks of the ``paper`` configs (DDRNet: 32 -> 64 -> 128 denoising net, 16/32/64
hypercolumns; DDD: channel steps 8 ... 128) on one 640x480 frame, as the methods do (normalisation,
holes, refinement on the grey image), with random weights (the time does not depend on their values),
against the suite's hole-aware bilateral filter in the same run (the ratio is the number that travels
between machines). Training: samples per second of the ``tiny`` configs' loss + backward + Adam step on
synthetic batches of their shapes (DDRNet: batches of 8 crops of 64x64; DDD: the shipped ``tiny`` config's
model, loss and batch size, four views of the demo's 320x240, splatting between them; its warm start, a
smoothing fit on 64x64 crops, is not timed). Runs are interleaved; the table gives medians.

Is the inference time the networks' arithmetic or waste? Each network's multiply-adds per frame are
counted (``torch.utils.flop_counter``) and its achieved GFLOP/s set against a large float32 matrix
product timed in the same run (the CPU's practical peak for this torch build): a ratio near 1 says the
time is the convolutions themselves, far below 1 that something else (copies, small kernels) costs.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from methods import get  # noqa: E402
from methods.ddd.model import LossConfig as DDDLoss, ModelConfig as DDDModel, batch_loss as ddd_loss, build as ddd_build, denoise_metres  # noqa: E402,E501
from methods.ddrnet.model import LossConfig, ModelConfig, batch_loss, build, grey_of, run_metres  # noqa: E402
from methods.tools.synthetic import synthetic_scene  # noqa: E402


def _median_ms(fns: dict, repeats: int) -> dict:
    for f in fns.values():
        f()
    t = {k: [] for k in fns}
    for _ in range(repeats):
        for k, f in fns.items():
            t0 = time.perf_counter()
            f()
            t[k].append(1000 * (time.perf_counter() - t0))
    return {k: float(np.median(v)) for k, v in t.items()}


def inference(repeats: int, device: str) -> dict:
    _, depth = synthetic_scene((480, 640), seed=0)
    color = np.random.default_rng(0).integers(0, 255, (480, 640, 3), dtype=np.uint8)
    d = torch.from_numpy(depth)[None, None].to(device)
    g = grey_of(torch.from_numpy(color.astype(np.float32) / 255).permute(2, 0, 1)[None]).to(device)
    torch.manual_seed(0)
    dn = build(ModelConfig(), refine=False).to(device).eval()
    dt = build(ModelConfig(), refine=True).to(device).eval()
    ddd = ddd_build(DDDModel()).to(device).eval()
    bf = get("bilateral")

    def sync(f):
        def run():
            with torch.no_grad():
                f()
            if device == "cuda":
                torch.cuda.synchronize()
        return run

    return _median_ms({"ddrnet": sync(lambda: run_metres(dn, d, None, d_min=0.2, d_max=6.0)),
                       "ddrnet_refine": sync(lambda: run_metres(dt, d, g, d_min=0.2, d_max=6.0)),
                       "ddd": sync(lambda: denoise_metres(ddd, d)),
                       "bilateral (reference)": lambda: bf.denoise(depth)}, repeats)


def gflops(device: str) -> dict:
    """GFLOP (2 x multiply-adds) of one 640x480 frame per network, counted by torch."""
    from torch.utils.flop_counter import FlopCounterMode

    d = torch.full((1, 1, 480, 640), 2.0, device=device)
    g = torch.rand(1, 1, 480, 640, device=device)
    torch.manual_seed(0)
    nets = {"ddrnet": (build(ModelConfig(), refine=False), lambda n: n(d, None)),
            "ddrnet_refine": (build(ModelConfig(), refine=True), lambda n: n(d, g)),
            "ddd": (ddd_build(DDDModel()), lambda n: n(d, torch.ones_like(d)))}
    out = {}
    for k, (net, call) in nets.items():
        counter = FlopCounterMode(display=False)
        with torch.no_grad(), counter:
            call(net.to(device).eval())
        out[k] = counter.get_total_flops() / 1e9
    return out


def matmul_gflops(repeats: int, device: str) -> float:
    """Achieved GFLOP/s of a 1024 x 1024 float32 matrix product (the reference for the networks)."""
    a, b = torch.randn(1024, 1024, device=device), torch.randn(1024, 1024, device=device)
    ms = _median_ms({"mm": lambda: torch.mm(a, b)}, max(repeats, 5) * 4)["mm"]
    return 2 * 1024 ** 3 / (ms / 1000) / 1e9


def _ddrnet_batch(b=8, s=64):
    rng = np.random.default_rng(0)
    ref = torch.from_numpy(rng.uniform(1.0, 3.0, (b, 1, 1, s, s)).astype(np.float32))
    return {"lq_depth": ref + 0.02 * torch.randn_like(ref), "reference": ref, "color": torch.rand(b, 1, 3, s, s),
            "roi": torch.ones(b, 1, 1, s, s), "camera": torch.tensor([[80.0, 80.0, 32.0, 32.0]]).expand(b, 4).clone()}


def _ddd_batch(b=2, v=4, h=120, w=160):
    """Four views ``(b, v, ., h, w)`` of a plane 2 m away, a person-sized block 0.5 m in front of it (the
    foreground the ``tiny`` loss weights), the cameras 0.2 m apart."""
    T = torch.eye(4).repeat(b, v, 1, 1)
    T[:, :, 0, 3] = torch.linspace(-0.3, 0.3, v)
    fg = torch.zeros(b, v, 1, h, w)
    fg[..., h // 4: 3 * h // 4, w // 3: 2 * w // 3] = 1.0
    depth = 2.0 - 0.5 * fg + 0.02 * torch.randn(b, v, 1, h, w)
    return {"depth": depth, "valid": torch.ones(b, v, 1, h, w), "foreground": fg,
            "color": torch.rand(b, v, 3, h, w),
            "camera": torch.tensor([w * 0.94, w * 0.94, w / 2, h / 2]).expand(b, v, 4).clone(), "T_rig": T}


def training(repeats: int) -> dict:
    from methods.ddd.train import DDDConfig
    from methods.nn.config import load_config

    ddd_tiny, _ = load_config("tiny", DDDConfig, family="ddd")
    out = {}
    tiny = dict(width=8, refine_width=8)
    for name, net, loss, batch in (
            ("ddrnet", build(ModelConfig(**tiny), refine=False), batch_loss(LossConfig(), d_min=0.2, d_max=6.0), _ddrnet_batch()),
            ("ddrnet_refine", build(ModelConfig(**tiny), refine=True), batch_loss(LossConfig(), d_min=0.2, d_max=6.0), _ddrnet_batch()),
            ("ddd", ddd_build(ddd_tiny.model), ddd_loss(ddd_tiny.loss),
             _ddd_batch(b=ddd_tiny.optim.batch_size, h=240, w=320))):
        opt = torch.optim.Adam(net.parameters(), lr=1e-3)

        def step():
            opt.zero_grad()
            total, _ = loss(net, batch)
            total.backward()
            opt.step()

        n = len(next(iter(batch.values())))
        out[name] = n / (_median_ms({name: step}, repeats)[name] / 1000)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--threads", type=int, default=2, help="torch CPU threads (default: 2)")
    ap.add_argument("--repeats", type=int, default=5, help="timed runs per item (default: 5)")
    ap.add_argument("--device", default="cpu", choices=("cpu", "cuda"), help="inference device (default: cpu)")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    # training first: after the 640x480 inference, the same training steps ran 20-30x slower in this
    # process (measured: ddrnet 1.8 instead of 57 samples/s), which is not what a training run sees
    train = training(args.repeats)
    inf = inference(args.repeats, args.device)
    flops, peak = gflops(args.device), matmul_gflops(args.repeats, args.device)
    ref = inf["bilateral (reference)"]
    print(f"inference, one 640x480 frame, {args.device}, {args.threads} CPU threads (median of {args.repeats}):")
    print(f"{'method':24s} {'ms/frame':>10s} {'x bilateral':>12s} {'GFLOP':>8s} {'GFLOP/s':>8s} {'x matmul':>9s}")
    for k, v in inf.items():
        f = flops.get(k)
        extra = f" {f:8.1f} {f / (v / 1000):8.1f} {f / (v / 1000) / peak:9.2f}" if f else ""
        print(f"{k:24s} {v:10.1f} {v / ref:12.2f}{extra}")
    print(f"reference: 1024x1024 float32 matrix product {peak:.1f} GFLOP/s")
    print(f"\ntraining, tiny configs, {args.threads} CPU threads (loss + backward + Adam step, median of {args.repeats}):")
    for k, v in train.items():
        print(f"{k:24s} {v:10.3g} samples/s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
