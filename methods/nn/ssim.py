"""Structural similarity (SSIM, Wang et al. 2004) as a differentiable torch map.

``S = (2 mu_x mu_y + C1)(2 s_xy + C2) / ((mu_x^2 + mu_y^2 + C1)(s_x^2 + s_y^2 + C2))`` with local
means and (population) covariances under a normalised Gaussian window of width ``sigma`` pixels
and radius ``radius`` (default ``int(3.5 sigma + 0.5)``: 11x11 for sigma 1.5), ``C1 = (0.01 L)^2``,
``C2 = (0.03 L)^2`` for data range ``L``. Borders are padded by mirror reflection with the edge
repeated, so the map equals ``skimage.metrics.structural_similarity(x, y, gaussian_weights=True,
sigma=1.5, use_sample_covariance=False, data_range=L, full=True)`` pixel for pixel.

DDD's released code uses a 5x5 window (``radius=2``) and zero padding; the window is an option.
"""
from __future__ import annotations


import torch
import torch.nn.functional as F


def gaussian_window(sigma: float, radius: int, *, like: torch.Tensor) -> torch.Tensor:
    """A normalised 1-D Gaussian, ``(2 radius + 1,)``."""
    x = torch.arange(-radius, radius + 1, dtype=torch.float64)
    g = torch.exp(-0.5 * (x / sigma) ** 2)
    return (g / g.sum()).to(dtype=like.dtype, device=like.device)


def _symmetric_pad(x: torch.Tensor, r: int) -> torch.Tensor:
    """Pad H and W by ``r`` mirroring with the edge repeated (numpy ``symmetric``, scipy ``reflect``)."""
    x = torch.cat([x[..., :r, :].flip(-2), x, x[..., -r:, :].flip(-2)], dim=-2)
    return torch.cat([x[..., :r].flip(-1), x, x[..., -r:].flip(-1)], dim=-1)


def _blur(x: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
    c = x.shape[1]
    r = (g.numel() - 1) // 2
    x = _symmetric_pad(x, r)
    x = F.conv2d(x, g.view(1, 1, 1, -1).expand(c, 1, 1, -1), groups=c)
    return F.conv2d(x, g.view(1, 1, -1, 1).expand(c, 1, -1, 1), groups=c)


def ssim_map(x: torch.Tensor, y: torch.Tensor, *, sigma: float = 1.5, radius: int | None = None,
             data_range: float = 1.0) -> torch.Tensor:
    """SSIM per pixel and channel of ``x``, ``y`` ``(B, C, H, W)`` (same units, range ``data_range``).

    Returns ``(B, C, H, W)`` in ``[-1, 1]``. ``radius=None``: ``int(3.5 sigma + 0.5)``. Images must
    be larger than the radius in both directions.
    """
    r = int(3.5 * sigma + 0.5) if radius is None else int(radius)
    if min(x.shape[-2:]) <= r:
        raise ValueError(f"ssim_map: images of {tuple(x.shape[-2:])} are too small for a window radius of {r}")
    g = gaussian_window(sigma, r, like=x)
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    mx, my = _blur(x, g), _blur(y, g)
    vx = _blur(x * x, g) - mx * mx
    vy = _blur(y * y, g) - my * my
    cxy = _blur(x * y, g) - mx * my
    return ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))


def ssim(x: torch.Tensor, y: torch.Tensor, *, sigma: float = 1.5, radius: int | None = None,
         data_range: float = 1.0) -> torch.Tensor:
    """Mean SSIM over the map without a border of ``radius`` pixels (scikit-image's ``mssim``)."""
    r = int(3.5 * sigma + 0.5) if radius is None else int(radius)
    m = ssim_map(x, y, sigma=sigma, radius=r, data_range=data_range)
    return m[..., r:m.shape[-2] - r, r:m.shape[-1] - r].mean()


__all__ = ["gaussian_window", "ssim", "ssim_map"]
