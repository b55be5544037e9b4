"""The two networks of DDRNet (seed section III-A, Fig. 5 and 6), as ``nn.Module``s.

Both work on *normalised* depth: metres clipped to ``[d_min, d_max]`` and mapped linearly to
``[-1, 1]`` (:func:`normalise_depth`; the released code uses 500-3000 mm); holes enter as ``-1``
(the released code's clipped zero).

:class:`DenoiseNet` (Fig. 5, DispNet-like): a 3x3 convolution to ``width`` channels, ``downs``
stride-2 3x3 convolutions doubling the channels (32 -> 64 -> 128), ``blocks`` residual blocks
without normalisation at the bottom, then per scale the skip of that scale concatenated and a
stride-2 3x3 transposed convolution halving the channels, the full-resolution skip concatenated,
a 3x3 convolution to one channel with ``tanh``, added to the input and clipped to ``[-1, 1]``.
Leaky ReLU (slope 0.2) everywhere else. Input sizes that are not multiples of ``2**downs`` are
padded (edge replicated) and cropped back. The last layers start small (:func:`_small`), so an
untrained net is nearly the identity.

:class:`RefineNet` (Fig. 6, hypercolumn): depth and grey-image branches (3x3, 8 channels each),
hypercolumns at three scales (16, 32, 64 channels; 2x2 max pooling between them; coarse maps
upsampled bilinearly to full resolution), three 1x1 layers (16, 4, 1) and ``tanh``. The released
code outputs that ``tanh`` as the refined depth; with ``residual=True`` (our default) it is added
to the denoised depth instead, as the denoising net does, so an untrained refinement starts from
``D_dn`` rather than from a flat map.
"""
from __future__ import annotations

import torch
import torch.nn as nn
import torch.nn.functional as F

SLOPE = 0.2


def normalise_depth(depth_m: torch.Tensor, *, d_min: float, d_max: float) -> torch.Tensor:
    """Metres (NaN or <= 0 = hole) -> ``[-1, 1]``; holes and depths below ``d_min`` give ``-1``."""
    d = torch.nan_to_num(depth_m, nan=d_min).clamp(d_min, d_max)
    return (d - d_min) / (d_max - d_min) * 2.0 - 1.0


def denormalise_depth(x: torch.Tensor, *, d_min: float, d_max: float) -> torch.Tensor:
    """``[-1, 1]`` -> metres (the inverse of :func:`normalise_depth` on its range)."""
    return (x + 1.0) * 0.5 * (d_max - d_min) + d_min


def _conv(cin: int, cout: int, k: int = 3, stride: int = 1) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, k, stride=stride, padding=k // 2)


def _small(conv: nn.Conv2d) -> None:
    """Scale a last layer's initial weights by 0.01 and zero its bias: the residual nets start near the
    identity (not exactly, so that every layer receives gradients from the first step)."""
    with torch.no_grad():
        conv.weight.mul_(0.01)
        conv.bias.zero_()


class ResidualBlock(nn.Module):
    """``x + conv(act(conv(x)))`` followed by the activation; no normalisation."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.c1, self.c2 = _conv(channels, channels), _conv(channels, channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.leaky_relu(x + self.c2(F.leaky_relu(self.c1(x), SLOPE)), SLOPE)


class DenoiseNet(nn.Module):
    """``(B, 1, H, W)`` normalised depth -> denoised normalised depth, same shape."""

    def __init__(self, *, width: int = 32, downs: int = 2, blocks: int = 2) -> None:
        super().__init__()
        self.downs = downs
        self.first = _conv(1, width)
        self.down = nn.ModuleList(_conv(width * 2 ** i, width * 2 ** (i + 1), stride=2) for i in range(downs))
        bottom = width * 2 ** downs
        self.blocks = nn.Sequential(*(ResidualBlock(bottom) for _ in range(blocks)))
        self.up = nn.ModuleList(
            nn.ConvTranspose2d(2 * width * 2 ** i, width * 2 ** (i - 1) if i > 0 else width, 3, stride=2,
                               padding=1, output_padding=1) for i in range(downs, 0, -1))
        self.last = _conv(2 * width, 1)
        _small(self.last)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h, w = x.shape[-2:]
        m = 2 ** self.downs
        ph, pw = (-h) % m, (-w) % m
        xp = F.pad(x, (0, pw, 0, ph), mode="replicate") if ph or pw else x
        skips = [F.leaky_relu(self.first(xp), SLOPE)]
        for conv in self.down:
            skips.append(F.leaky_relu(conv(skips[-1]), SLOPE))
        y = self.blocks(skips[-1])
        for up in self.up:
            y = F.leaky_relu(up(torch.cat([skips.pop(), y], dim=1)), SLOPE)
        y = torch.tanh(self.last(torch.cat([skips.pop(), y], dim=1)))
        return (xp + y).clamp(-1.0, 1.0)[..., :h, :w]


class RefineNet(nn.Module):
    """Normalised depth ``(B, 1, H, W)`` and grey image ``(B, 1, H, W)`` in ``[-1, 1]`` -> refined depth."""

    def __init__(self, *, width: int = 16, residual: bool = True) -> None:
        super().__init__()
        self.residual = residual
        half = width // 2
        self.c1_d, self.c1_c = _conv(1, half), _conv(1, half)
        self.c2 = _conv(width, width)
        self.c3, self.c4 = _conv(2 * width, 2 * width), _conv(2 * width, 2 * width)
        self.c5, self.c6, self.c7 = _conv(4 * width, 4 * width), _conv(4 * width, 4 * width), _conv(4 * width, 4 * width)
        self.f1, self.f2, self.f3 = _conv(7 * width, width, 1), _conv(width, max(1, width // 4), 1), _conv(max(1, width // 4), 1, 1)
        if residual:
            _small(self.f3)

    def forward(self, depth: torch.Tensor, grey: torch.Tensor) -> torch.Tensor:
        act = lambda t: F.leaky_relu(t, SLOPE)  # noqa: E731
        h, w = depth.shape[-2:]
        c1 = torch.cat([act(self.c1_d(depth)), act(self.c1_c(grey))], dim=1)
        c2 = act(self.c2(c1))
        c3 = act(self.c3(F.max_pool2d(torch.cat([c1, c2], dim=1), 2, ceil_mode=True)))
        c4 = act(self.c4(c3))
        c5 = act(self.c5(F.max_pool2d(torch.cat([c3, c4], dim=1), 2, ceil_mode=True)))
        c7 = act(self.c7(act(self.c6(c5))))
        up = lambda t: F.interpolate(t, size=(h, w), mode="bilinear", align_corners=False)  # noqa: E731
        y = act(self.f2(act(self.f1(torch.cat([c2, up(c4), up(c7)], dim=1)))))
        y = torch.tanh(self.f3(y))
        return (depth + y).clamp(-1.0, 1.0) if self.residual else y


class DDRNet(nn.Module):
    """Denoising net, optionally followed by the refinement net (``refine=True``, the paper's pipeline).

    ``forward(depth, grey)`` returns ``(d_dn, d_dt)`` (normalised); ``d_dt`` is ``None`` without refinement.
    """

    def __init__(self, *, refine: bool, width: int = 32, refine_width: int = 16, residual_refine: bool = True) -> None:
        super().__init__()
        self.denoise = DenoiseNet(width=width)
        self.refine = RefineNet(width=refine_width, residual=residual_refine) if refine else None

    def forward(self, depth: torch.Tensor, grey: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor | None]:
        d_dn = self.denoise(depth)
        if self.refine is None:
            return d_dn, None
        if grey is None:
            raise ValueError("DDRNet with refinement needs the grey image")
        return d_dn, self.refine(d_dn, grey)
