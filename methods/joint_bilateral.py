"""Hole-aware joint (cross) bilateral filter of depth guided by the colour image.

Eq. 5-8 with the range kernel on the colour guide ``C`` instead of the depth::

    h(p) = 1/k(p) * sum_q exp(-|q - p|^2 / (2 sigma_spatial^2) - |C(q) - C(p)|^2 / (2 sigma_color^2)) f(q)

``|C(q) - C(p)|`` is the Euclidean distance of the colours (eq. 8's ``delta``; all three channels,
in the guide's own units: 0-255 for 8-bit colour). ``q`` runs over the disk ``|q - p| <= radius``
and only over pixels with a depth; holes stay holes unless ``fill_holes=True``, in which case they
get the colour-weighted mean of the valid depths around them (the colour is known at a hole).
Sterzentsko et al. (DDD) compare against this filter.

Note: OpenCV's ``ximgproc.jointBilateralFilter`` measures colour distance as the sum of absolute
channel differences (L1) and interpolates ``exp`` from a table; this one follows eq. 8 (L2).
"""
from __future__ import annotations

import numpy as np

from methods._defaults import shared_help, swept
from methods._kernels import joint_mean
from methods.base import (Denoiser, check_color, check_depth, check_flag, check_radius, check_sigma, guide_planes)

from methods.errors import MethodError

NAME = "joint_bilateral"


def _resolve(sigma_spatial, sigma_color, radius, fill_holes):
    d = swept(NAME)
    sigma_spatial = check_sigma(d["sigma_spatial"] if sigma_spatial is None else sigma_spatial, "sigma_spatial",
                                method=NAME, unit="pixels")
    sigma_color = check_sigma(d["sigma_color"] if sigma_color is None else sigma_color, "sigma_color",
                              method=NAME, unit="colour levels", allow_inf=True)
    radius = check_radius(radius, sigma_spatial, method=NAME)
    return sigma_spatial, sigma_color, radius, check_flag(fill_holes, "fill_holes", method=NAME)


def joint_bilateral_filter(depth: np.ndarray, guide: np.ndarray, *, sigma_spatial: float | None = None,
                           sigma_color: float | None = None, radius: int | None = None,
                           fill_holes: bool = False) -> np.ndarray:
    """Hole-aware joint bilateral filter of ``depth`` with the range kernel on ``guide``.

    Args:
        depth: ``(H, W)`` float32 metres, NaN holes.
        guide: ``(H, W, 3)`` RGB or ``(H, W)`` grey image of the same size; uint8, uint16 or float32.
        sigma_spatial: spatial Gaussian width in pixels; ``None``: the swept default.
        sigma_color: range Gaussian width in the guide's units (0-255 levels for uint8 colour);
            ``inf`` turns the range kernel off. ``None``: the swept default.
        radius: disk radius in pixels; ``None``: ``max(1, ceil(2 * sigma_spatial))``.
        fill_holes: holes get the colour-weighted mean of the valid depths around them.

    Returns:
        ``(H, W)`` float32 metres, NaN where ``depth`` is NaN (unless ``fill_holes``).

    Example:
        >>> import numpy as np
        >>> rng = np.random.default_rng(0)
        >>> depth = (2.0 + 0.01 * rng.standard_normal((32, 32))).astype(np.float32)
        >>> color = np.zeros((32, 32, 3), np.uint8); color[:, 16:] = 200
        >>> out = joint_bilateral_filter(depth, color, sigma_spatial=2.0, sigma_color=10.0)
        >>> out.shape, out.dtype
        ((32, 32), dtype('float32'))
    """
    depth = check_depth(depth)
    if guide is None:
        raise MethodError(f"{NAME}: needs the colour image as its guide")
    guide = check_color(guide, depth)
    sigma_spatial, sigma_color, radius, fill_holes = _resolve(sigma_spatial, sigma_color, radius, fill_holes)
    out = joint_mean(depth, guide_planes(guide), 0.5 / sigma_color ** 2, sigma_spatial=sigma_spatial, radius=radius)
    if not fill_holes:
        out[~np.isfinite(depth)] = np.nan
    return out


class JointBilateralFilter(Denoiser):
    """Joint bilateral filter guided by the colour image; see :func:`joint_bilateral_filter`."""

    name = NAME
    version = "1"
    description = "joint bilateral filter: range kernel on the colour image (L2, 0-255 units), hole-aware"
    uses_color = True
    defaults = {"sigma_spatial": None, "sigma_color": None, "radius": None, "fill_holes": False, **swept(NAME)}
    param_help = {
        "sigma_spatial": "spatial Gaussian width, pixels",
        "sigma_color": "range Gaussian width on the colour guide, 0-255 levels (Euclidean over RGB); inf = off",
        **shared_help("radius"),
        "fill_holes": "true: holes get the colour-weighted mean of the valid depths around them",
    }

    def check_params(self, params):
        _resolve(**params)

    def _denoise(self, depth, color, camera):
        if color is None:
            raise MethodError(f"{NAME}: needs the colour image (the dataset has no LQ colour)")
        return joint_bilateral_filter(depth, color, **self.params)
