"""Depth normalisation of the networks' inputs (pure functions on tensors).

Depth is metres, NaN where the sensor measured nothing. A network sees

    x = (clip(d, d_min, d_max) - d_min) / (d_max - d_min)        in [0, 1], holes -> 0,

plus (where configured) the validity mask ``isfinite(d)`` as its own channel, so a hole is never
confused with a near surface. Outputs are mapped back with :func:`denormalize_depth`; losses are
computed in metres. ``d_min``/``d_max`` come from the config's ``data`` section (defaults 0.2 and
6 m: every sensor the suite knows measures inside that range).

Centred coding (``data.depth_scale_m > 0``, :func:`encode_depth`): a denoiser needs the local
structure, not the absolute range. With the range coding, centimetres of noise are 0.002-0.005
units of a 5.8 m range and a residual network has to output corrections of that size (SSDD's UNet
stayed at the identity with it, even trained against the simulator's truth). The centred coding

    c = median of the frame's valid depth,    x = (d - c) / depth_scale_m,    holes -> 0,

puts 1 cm at 0.1 units for ``depth_scale_m = 0.1`` and makes the code independent of how far the
scene is; outputs map back with the same ``c`` (:func:`decode_depth`).

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


def frame_centre(depth: torch.Tensor) -> torch.Tensor:
    """Median of the valid depth of each frame ``(..., C, H, W)`` -> ``(..., 1, 1, 1)`` (1 m for an empty frame)."""
    flat = depth.reshape(*depth.shape[:-3], -1)
    med = torch.nanmedian(flat, dim=-1).values if flat.shape[-1] else torch.ones(flat.shape[:-1])
    return torch.nan_to_num(med, nan=1.0)[..., None, None, None]


def encode_depth(depth: torch.Tensor, *, d_min: float, d_max: float, scale_m: float = 0.0,
                 centre: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
    """A network's depth code: ``depth`` ``(..., C, H, W)`` metres, NaN holes -> ``(x, valid, centre)``.

    ``scale_m = 0``: the range coding of :func:`normalize_depth` (``centre`` None). ``scale_m > 0``:
    ``x = (d - centre) / scale_m`` with ``centre`` the frame's median (:func:`frame_centre`) unless
    given (to code a second layer of the same frame alike); holes are 0, ``valid`` is 0/1 float.
    """
    if scale_m <= 0:
        x, valid = normalize_depth(depth, d_min=d_min, d_max=d_max)
        return x, valid, None
    centre = frame_centre(depth) if centre is None else centre
    ok = torch.isfinite(depth)
    x = torch.where(ok, (depth - centre) / scale_m, torch.zeros_like(depth))
    return x, ok.to(depth.dtype), centre


def decode_depth(x: torch.Tensor, *, d_min: float, d_max: float, scale_m: float = 0.0,
                 centre: torch.Tensor | None = None) -> torch.Tensor:
    """Inverse of :func:`encode_depth` (metres), with the ``centre`` it returned."""
    if scale_m <= 0:
        return denormalize_depth(x, d_min=d_min, d_max=d_max)
    return x * scale_m + centre
