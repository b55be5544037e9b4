"""Partial convolution (Liu et al. 2018), the layer of DDD's autoencoder (seed Fig. 7).

For input ``x`` ``(B, C, H, W)`` and a validity mask ``m`` ``(B, 1, H, W)`` (1 = measured):

    y = W * (x m) * (k^2 / sum(m in window)) + b     where the window holds a valid pixel,
    y = 0                                           elsewhere,
    m' = 1 where the window holds a valid pixel, else 0

so values under holes never reach the output, sums over partly valid windows are rescaled to a
full window, and the mask ``m'`` (a dilation of ``m`` for stride 1) is handed to the next layer.
"""
from __future__ import annotations

import torch
import torch.nn as nn
import torch.nn.functional as F


def partial_conv2d(x: torch.Tensor, mask: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None, *,
                   stride: int = 1, padding: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """The pure function: ``(y, m')`` as in the module docstring; ``weight`` ``(Cout, Cin, k, k)``."""
    k = weight.shape[-2] * weight.shape[-1]
    with torch.no_grad():
        ones = torch.ones(1, 1, *weight.shape[-2:], dtype=x.dtype, device=x.device)
        count = F.conv2d(mask.to(x.dtype), ones, stride=stride, padding=padding)
        new_mask = (count > 0).to(x.dtype)
        scale = k / count.clamp_min(1.0) * new_mask
    y = F.conv2d(x * mask.to(x.dtype), weight, None, stride=stride, padding=padding) * scale
    if bias is not None:
        y = (y + bias.view(1, -1, 1, 1)) * new_mask
    return y, new_mask


class PartialConv2d(nn.Conv2d):
    """``nn.Conv2d`` whose ``forward(x, mask)`` is :func:`partial_conv2d` (square kernel, 'same' padding)."""

    def __init__(self, cin: int, cout: int, kernel_size: int = 3, *, stride: int = 1, bias: bool = True) -> None:
        super().__init__(cin, cout, kernel_size, stride=stride, padding=kernel_size // 2, bias=bias)

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:  # type: ignore[override]
        return partial_conv2d(x, mask, self.weight, self.bias, stride=self.stride[0], padding=self.padding[0])


class PartialBlock(nn.Module):
    """Partial convolution followed by ELU (``act=False``: no activation)."""

    def __init__(self, cin: int, cout: int, kernel_size: int = 3, *, stride: int = 1, act: bool = True) -> None:
        super().__init__()
        self.conv = PartialConv2d(cin, cout, kernel_size, stride=stride)
        self.act = act

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        y, m = self.conv(x, mask)
        return (F.elu(y) if self.act else y), m


class PartialResidual(nn.Module):
    """Pre-activated residual block of two 3x3 partial convolutions: ``x + pc(elu(pc(elu(x))))``."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.c1, self.c2 = PartialConv2d(channels, channels), PartialConv2d(channels, channels)

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        y, m = self.c1(F.elu(x), mask)
        y, m = self.c2(F.elu(y), m)
        return x + y, m
