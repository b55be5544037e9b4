"""A self-supervised warm start for DDD's autoencoder (not in the paper; the ``tiny`` config uses it).

Why: the residual network starts at the identity (:mod:`methods.ddd.net`), and there eq. 22 has a
sticky minimum: BerHu's threshold ``c = 0.2 max |r|`` shrinks with the residual, so any output change
costs at least its L1 norm, while the photometric and surface terms gain only along the few weight
directions that correlate with the noise. In a few hundred CPU steps the net stays at the identity
(measured: held-out MAE within 0.1 mm of the raw depth after 100 steps at learning rates 1e-3 and
3e-3), and with a smaller BerHu weight it escapes into a depth offset that flattens every normal
(the surface prior's trivial minimum), not into denoising.

The warm start first fits the network, on random crops of the training views, to reproduce a
hole-aware Gaussian smoothing of **its own input**:

    target(p) = sum_q g_sigma(p - q) M(q) D(q) / sum_q g_sigma(p - q) M(q)        (M: measured pixels)

with an L1 loss over measured pixels. This reads nothing but the input depth (no truth, no HQ
reference, no other view): the training stays self-supervised. It gives the network features that
follow the local depth, from which eq. 22 then moves it towards what the multi-view photometric
consistency and the surface prior ask for; the warm-started net alone is a poor smoother (the fit is
short) and is not the result: eq. 22 training follows it.

Shapes: depth ``(B, 1, H, W)`` metres with 0 at holes, mask ``(B, 1, H, W)`` 1 = measured.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F


@dataclass
class WarmupConfig:
    """``steps`` Adam steps (0: no warm start, the paper) at ``lr`` on ``batch`` random ``crop``-pixel
    crops of single views; the target's Gaussian ``sigma_px`` (pixels)."""

    steps: int = 0
    lr: float = 3e-3
    batch: int = 8
    crop: int = 64
    sigma_px: float = 1.0

    def __post_init__(self) -> None:
        if self.steps < 0 or self.lr <= 0 or self.batch < 1 or self.crop < 8 or self.sigma_px <= 0:
            raise ValueError("warmup: steps >= 0, lr > 0, batch >= 1, crop >= 8 and sigma_px > 0 required")


def smoothed_input(depth: torch.Tensor, mask: torch.Tensor, *, sigma_px: float) -> torch.Tensor:
    """The warm start's target: hole-aware Gaussian smoothing of ``depth`` (module docstring);
    0 where no measured pixel lies within ``3 sigma``."""
    r = max(1, int(3 * sigma_px))
    x = torch.arange(-r, r + 1, dtype=depth.dtype, device=depth.device)
    g = torch.exp(-x * x / (2 * sigma_px * sigma_px))
    m = mask.to(depth.dtype)

    def blur(img: torch.Tensor) -> torch.Tensor:   # separable: a column pass, then a row pass
        img = F.conv2d(img, g.view(1, 1, -1, 1), padding=(r, 0))
        return F.conv2d(img, g.view(1, 1, 1, -1), padding=(0, r))

    num = blur(depth * m)
    den = blur(m)
    return torch.where(den > 1e-6, num / den.clamp_min(1e-6), torch.zeros_like(num))


def warmup_loss(net: nn.Module, depth: torch.Tensor, mask: torch.Tensor, *, sigma_px: float) -> torch.Tensor:
    """Mean ``|net(D) - target|`` over measured pixels (metres)."""
    target = smoothed_input(depth, mask, sigma_px=sigma_px)
    err = (net(depth, mask) - target).abs() * mask
    return err.sum() / mask.sum().clamp_min(1.0)


def random_crops(views: list[tuple[torch.Tensor, torch.Tensor]], rng: np.random.Generator, *, batch: int,
                 crop: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``batch`` random ``crop x crop`` windows of random views ``(depth (1, H, W), mask (1, H, W))``."""
    ds, ms = [], []
    for _ in range(batch):
        d, m = views[rng.integers(len(views))]
        h, w = d.shape[-2:]
        c = min(crop, h, w)
        y, x = rng.integers(0, h - c + 1), rng.integers(0, w - c + 1)
        ds.append(d[:, y:y + c, x:x + c])
        ms.append(m[:, y:y + c, x:x + c])
    return torch.stack(ds), torch.stack(ms)


def warm_start(net: nn.Module, views: list[tuple[torch.Tensor, torch.Tensor]], cfg: WarmupConfig, *,
               seed: int = 0) -> nn.Module:
    """Fit ``net`` for ``cfg.steps`` steps to :func:`smoothed_input` of crops of ``views``; returns ``net``."""
    if cfg.steps == 0 or not views:
        return net
    rng = np.random.default_rng(seed)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    net.train()
    for _ in range(cfg.steps):
        d, m = random_crops(views, rng, batch=cfg.batch, crop=cfg.crop)
        opt.zero_grad()
        warmup_loss(net, d, m, sigma_px=cfg.sigma_px).backward()
        opt.step()
    return net
