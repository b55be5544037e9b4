"""Depth normalisation of the networks' inputs (pure functions on tensors).

Depth is metres, NaN where the sensor measured nothing. A network sees

    x = (clip(d, d_min, d_max) - d_min) / (d_max - d_min)        in [0, 1], holes -> 0,

plus (where configured) the validity mask ``isfinite(d)`` as its own channel, so a hole is never
confused with a near surface. Outputs are mapped back with :func:`denormalize_depth`; losses are
computed in metres. ``d_min``/``d_max`` come from the config's ``data`` section (defaults 0.2 and
6 m: every sensor the suite knows measures inside that range).

Colour (RGB uint8 on disk) is fed as float in [0, 1].
"""
from __future__ import annotations

import torch


def normalize_depth(depth: torch.Tensor, *, d_min: float, d_max: float) -> tuple[torch.Tensor, torch.Tensor]:
    """``depth`` (any shape, metres, NaN holes) -> ``(x, valid)``: x in [0, 1] with holes at 0, valid 0/1 float."""
    valid = torch.isfinite(depth)
    x = (depth.clamp(d_min, d_max) - d_min) / (d_max - d_min)
    return torch.where(valid, x, torch.zeros_like(x)), valid.to(depth.dtype)


def denormalize_depth(x: torch.Tensor, *, d_min: float, d_max: float) -> torch.Tensor:
    """Inverse of :func:`normalize_depth` on valid pixels: metres."""
    return x * (d_max - d_min) + d_min
