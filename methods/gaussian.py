"""Hole-aware normalised Gaussian on depth (the domain filter of eq. 1-2 with eq. 7; eq. 10).

    G(p) = 1/K(p) * sum_q exp(-|p - q|^2 / (2 sigma_spatial^2)) I(q),   K(p) = sum_q exp(...)

with ``q`` over the disk ``|q - p| <= radius`` and only over pixels with a depth. It is the first
pass of the rolling guidance filter (:mod:`methods.rolling_guidance`) and a baseline of its own.
"""
from __future__ import annotations

import numpy as np

from methods._defaults import shared_help, swept
from methods._kernels import gaussian_mean
from methods.base import Denoiser, check_depth, check_flag, check_radius, check_sigma

NAME = "gaussian"


def _resolve(sigma_spatial, radius, fill_holes, method=NAME):
    sigma_spatial = check_sigma(swept(NAME)["sigma_spatial"] if sigma_spatial is None else sigma_spatial,
                                "sigma_spatial", method=method, unit="pixels")
    radius = check_radius(radius, sigma_spatial, method=method)
    return sigma_spatial, radius, check_flag(fill_holes, "fill_holes", method=method)


def gaussian_filter(depth: np.ndarray, *, sigma_spatial: float | None = None, radius: int | None = None,
                    fill_holes: bool = False) -> np.ndarray:
    """Hole-aware normalised Gaussian of a depth map (eq. 10 over valid pixels).

    Args:
        depth: ``(H, W)`` float32 metres, NaN holes.
        sigma_spatial: Gaussian width in pixels; ``None``: the swept default.
        radius: disk radius in pixels; ``None``: ``max(1, ceil(2 * sigma_spatial))``.
        fill_holes: holes get the Gaussian mean of the valid depths in their window.

    Returns:
        ``(H, W)`` float32 metres, NaN where ``depth`` is NaN (unless ``fill_holes``).

    Example:
        >>> import numpy as np
        >>> depth = np.full((8, 8), 2.0, np.float32); depth[0, 0] = np.nan
        >>> out = gaussian_filter(depth, sigma_spatial=1.0)
        >>> bool(np.isnan(out[0, 0])), float(out[4, 4])
        (True, 2.0)
    """
    depth = check_depth(depth)
    sigma_spatial, radius, fill_holes = _resolve(sigma_spatial, radius, fill_holes)
    out = gaussian_mean(depth, sigma_spatial=sigma_spatial, radius=radius)
    if not fill_holes:
        out[~np.isfinite(depth)] = np.nan
    return out


class GaussianFilter(Denoiser):
    """Hole-aware normalised Gaussian; see :func:`gaussian_filter`."""

    name = NAME
    version = "1"
    description = "normalised Gaussian over valid depth (eq. 1-2, 10): the range-blind baseline"
    defaults = {"sigma_spatial": None, "radius": None, "fill_holes": False, **swept(NAME)}
    param_help = {
        "sigma_spatial": "Gaussian width, pixels",
        **shared_help("radius"),
        "fill_holes": "true: holes get the Gaussian mean of the valid depths around them",
    }

    def check_params(self, params):
        _resolve(**params)

    def _denoise(self, depth, color, camera):
        return gaussian_filter(depth, **self.params)
