"""DDD's fully convolutional autoencoder (seed Fig. 7): a shallow UNet of partial convolutions.

Channel steps ``8, 16, 32, 64, 128`` (``width`` times 1, 2, 4, 8, 16) from the top to the bottom:

    encoder  7x7 pconv 1->8, 5x5 pconv 8->16                      (full res., skip 1)
             3x3 pconv /2 16->32, 3x3 pconv 32->32                (1/2, skip 2)
             3x3 pconv /2 32->64, 3x3 pconv 64->64                (1/4, skip 3)
    bottom   3x3 pconv /2 64->128, two pre-activated partial residual blocks (1/8)
    decoder  per scale: nearest upsampling (features and mask), 3x3 pconv to the skip's channels,
             the skip concatenated, 1x1 convolution + ELU back to the skip's channels, 3x3 pconv
    output   3x3 pconv 16->8, 3x3 pconv 8->1 (no activation)

ELU after every layer but the last; the validity mask is propagated through every partial
convolution (holes of the input never reach the output, the mask grows by the kernels). Sizes
not divisible by 8 are padded (zeros, mask 0) and cropped back.

The released network regresses the depth directly (and stops at 64 channels); ``residual=True``
(default) adds the input depth where it is valid, and its last layer starts 100x smaller than the
default initialisation, so the untrained network is nearly the identity on measured pixels, which
short CPU trainings need. Depth in and out is metres.

``input_scale_m`` (None or 0: off, the released code's metres in) codes the input as
``(D - mean) / input_scale_m`` over the frame's measured pixels, and scales the residual back by
``input_scale_m`` (needs ``residual``): the noise, centimetres on a depth of metres, is then not a 1 %
ripple on a large offset (the ``tiny`` config: 0.1 m).

``highpass_px`` (0: off, the paper) keeps only the high frequencies of the network's correction: the
correction ``c`` (output minus input on measured pixels) becomes ``c - G(c)``, ``G`` the hole-aware
Gaussian mean over measured pixels with that sigma in pixels (:func:`methods.ddd.warmup.smoothed_input`).
A denoiser removes zero-mean noise; it has no business moving a surface by a smooth offset, which is
the cheap direction eq. 22's splatting and surface terms offer the small ``tiny`` network (measured:
people pulled 4-11 mm towards the camera). Needs ``residual``; the sigma is in pixels of the image the
network runs on (trained at half resolution and run at full, it is twice as wide in the scene).
"""
from __future__ import annotations

import torch
import torch.nn as nn
import torch.nn.functional as F

from methods.ddd.partial_conv import PartialBlock, PartialResidual
from methods.ddd.warmup import smoothed_input


class _Up(nn.Module):
    def __init__(self, cin: int, cout: int) -> None:
        super().__init__()
        self.pre = PartialBlock(cin, cout)
        self.fuse = nn.Conv2d(2 * cout, cout, 1)
        self.post = PartialBlock(cout, cout)

    def forward(self, x, mask, skip):
        x = F.interpolate(x, size=skip.shape[-2:], mode="nearest")
        mask = F.interpolate(mask, size=skip.shape[-2:], mode="nearest")
        x, mask = self.pre(x, mask)
        x = F.elu(self.fuse(torch.cat([x, skip], dim=1)))
        return self.post(x, mask)


class DDDNet(nn.Module):
    """``forward(depth, mask)``: depth ``(B, 1, H, W)`` metres (0 at holes), mask ``(B, 1, H, W)`` -> depth."""

    def __init__(self, *, width: int = 8, residual: bool = True, input_scale_m: float | None = None,
                 highpass_px: float | None = None) -> None:
        super().__init__()
        c = [width * 2 ** i for i in range(5)]  # 8, 16, 32, 64, 128
        if (input_scale_m or highpass_px) and not residual:
            raise ValueError("input_scale_m and highpass_px need residual=True")
        self.residual, self.input_scale_m = residual, float(input_scale_m or 0.0)
        self.highpass_px = float(highpass_px or 0.0)
        self.e1 = nn.ModuleList([PartialBlock(1, c[0], 7), PartialBlock(c[0], c[1], 5)])
        self.e2 = nn.ModuleList([PartialBlock(c[1], c[2], stride=2), PartialBlock(c[2], c[2])])
        self.e3 = nn.ModuleList([PartialBlock(c[2], c[3], stride=2), PartialBlock(c[3], c[3])])
        self.bottom = PartialBlock(c[3], c[4], stride=2)
        self.res = nn.ModuleList([PartialResidual(c[4]), PartialResidual(c[4])])
        self.up3, self.up2, self.up1 = _Up(c[4], c[3]), _Up(c[3], c[2]), _Up(c[2], c[1])
        self.out1 = PartialBlock(c[1], c[0])
        self.out2 = PartialBlock(c[0], 1, act=False)
        if residual:  # start near the identity: a small last layer (not zero, so every layer gets gradients)
            with torch.no_grad():
                self.out2.conv.weight.mul_(0.01)
                self.out2.conv.bias.zero_()

    @staticmethod
    def _run(layers, x, m):
        for layer in layers:
            x, m = layer(x, m)
        return x, m

    def forward(self, depth: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        mask = mask.to(depth.dtype)
        if not (self.input_scale_m or self.highpass_px):
            return self._forward(depth, mask)
        s = self.input_scale_m or 1.0
        mean = (depth * mask).sum((1, 2, 3), keepdim=True) / mask.sum((1, 2, 3), keepdim=True).clamp_min(1.0) \
            if self.input_scale_m else 0.0
        correction = self._forward((depth - mean) / s * mask, mask, residual=False)
        if self.highpass_px:
            correction = correction - smoothed_input(correction, mask, sigma_px=self.highpass_px)
        return depth * mask + s * correction

    def _forward(self, depth: torch.Tensor, mask: torch.Tensor, *, residual: bool | None = None) -> torch.Tensor:
        h, w = depth.shape[-2:]
        ph, pw = (-h) % 8, (-w) % 8
        d = F.pad(depth * mask, (0, pw, 0, ph))
        m = F.pad(mask, (0, pw, 0, ph))
        s1, m1 = self._run(self.e1, d, m)
        s2, m2 = self._run(self.e2, s1, m1)
        s3, m3 = self._run(self.e3, s2, m2)
        x, mb = self.bottom(s3, m3)
        x, mb = self._run(self.res, x, mb)
        x, mb = self.up3(x, mb, s3)
        x, mb = self.up2(x, mb, s2)
        x, mb = self.up1(x, mb, s1)
        x, mb = self.out1(x, mb)
        x, _ = self.out2(x, mb)
        x = x[..., :h, :w]
        return depth * mask + x if (self.residual if residual is None else residual) else x
