"""Building blocks of the suite's convolutional networks.

Networks avoid batch normalisation on purpose: its statistics depend on how a batch is split over
processes, which would break "two processes give the weights of one" (:mod:`methods.nn.trainer`),
and on the batch at inference. Blocks use GroupNorm (per sample) where a norm helps.
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


class ConvBlock(nn.Module):
    """Two 3x3 convolutions, each followed by GroupNorm and LeakyReLU: ``(B, c_in, H, W) -> (B, c_out, H, W)``."""

    def __init__(self, c_in: int, c_out: int) -> None:
        super().__init__()
        self.body = nn.Sequential(
            nn.Conv2d(c_in, c_out, 3, padding=1), nn.GroupNorm(_groups(c_out), c_out), nn.LeakyReLU(0.1, inplace=True),
            nn.Conv2d(c_out, c_out, 3, padding=1), nn.GroupNorm(_groups(c_out), c_out), nn.LeakyReLU(0.1, inplace=True))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.body(x)


class Down(nn.Module):
    """Halve the resolution (2x2 max pool), then a :class:`ConvBlock`."""

    def __init__(self, c_in: int, c_out: int) -> None:
        super().__init__()
        self.block = ConvBlock(c_in, c_out)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.block(F.max_pool2d(x, 2))


class Up(nn.Module):
    """Double the resolution (bilinear), concatenate the skip connection, then a :class:`ConvBlock`.

    Odd sizes are handled: the upsampled map is resized to the skip's size.
    """

    def __init__(self, c_in: int, c_skip: int, c_out: int) -> None:
        super().__init__()
        self.block = ConvBlock(c_in + c_skip, c_out)

    def forward(self, x: torch.Tensor, skip: torch.Tensor) -> torch.Tensor:
        x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
        return self.block(torch.cat([x, skip], dim=1))


def level_widths(width: int, levels: int) -> list[int]:
    """Channels per UNet level: ``width * 2**i`` for ``i < levels`` (e.g. 16, 32, 64, 128)."""
    return [width * (2 ** i) for i in range(levels)]
