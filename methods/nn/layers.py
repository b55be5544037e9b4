"""Building blocks of the suite's convolutional networks.

Networks avoid batch normalisation on purpose: its statistics depend on how a batch is split over
processes, which would break "two processes give the weights of one" (:mod:`methods.nn.trainer`),
and on the batch at inference. Blocks use GroupNorm (per sample) where a norm helps, or no norm
(``norm="none"``): a per-sample norm makes a block blind to the scale of its input, and a
denoiser whose correction must be proportional to the noise (a residual in depth units) cannot
learn through it (SSDD's nets stayed at the identity with GroupNorm; see methods/ssdd/networks.py).
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


def _groups(channels: int) -> int:
    for g in (8, 4, 2):
        if channels % g == 0 and channels // g >= 2:
            return g
    return 1


NORMS = ("group", "none")


def _norm(kind: str, channels: int) -> nn.Module:
    if kind not in NORMS:
        raise ValueError(f"norm must be one of {', '.join(NORMS)}, got {kind!r}")
    return nn.GroupNorm(_groups(channels), channels) if kind == "group" else nn.Identity()


class ConvBlock(nn.Module):
    """Two 3x3 convolutions, each followed by a norm (GroupNorm, or none with ``norm="none"``) and
    LeakyReLU: ``(B, c_in, H, W) -> (B, c_out, H, W)``."""

    def __init__(self, c_in: int, c_out: int, *, norm: str = "group") -> None:
        super().__init__()
        self.body = nn.Sequential(
            nn.Conv2d(c_in, c_out, 3, padding=1), _norm(norm, c_out), nn.LeakyReLU(0.1, inplace=True),
            nn.Conv2d(c_out, c_out, 3, padding=1), _norm(norm, c_out), nn.LeakyReLU(0.1, inplace=True))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.body(x)


class Down(nn.Module):
    """Halve the resolution (2x2 max pool), then a :class:`ConvBlock`."""

    def __init__(self, c_in: int, c_out: int, *, norm: str = "group") -> None:
        super().__init__()
        self.block = ConvBlock(c_in, c_out, norm=norm)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.block(F.max_pool2d(x, 2))


class Up(nn.Module):
    """Double the resolution (bilinear), concatenate the skip connection, then a :class:`ConvBlock`.

    Odd sizes are handled: the upsampled map is resized to the skip's size.
    """

    def __init__(self, c_in: int, c_skip: int, c_out: int, *, norm: str = "group") -> None:
        super().__init__()
        self.block = ConvBlock(c_in + c_skip, c_out, norm=norm)

    def forward(self, x: torch.Tensor, skip: torch.Tensor) -> torch.Tensor:
        x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
        return self.block(torch.cat([x, skip], dim=1))


def level_widths(width: int, levels: int) -> list[int]:
    """Channels per UNet level: ``width * 2**i`` for ``i < levels`` (e.g. 16, 32, 64, 128)."""
    return [width * (2 ** i) for i in range(levels)]
