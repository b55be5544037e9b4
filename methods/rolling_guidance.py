"""Hole-aware Rolling Guidance Filter as Zhang et al. (ECCV 2014) define it (seed report eq. 9-11).

1. Small-structure removal: ``J^1 = G``, the normalised Gaussian of the input (eq. 10)::

       J^1(p) = 1/K_p * sum_q exp(-|p - q|^2 / (2 sigma_spatial^2)) I(q)

2. Edge recovery: ``iterations - 1`` joint bilateral passes **of the input I** guided by the
   previous iterate (eq. 11)::

       J^{t+1}(p) = 1/K_p * sum_q exp(-|p - q|^2 / (2 sigma_spatial^2)
                                      - (J^t(p) - J^t(q))^2 / (2 sigma_color^2)) I(q)

``iterations`` counts the Gaussian pass, as in the authors' code (their ``J^0`` is a constant, which
makes the first joint pass a Gaussian): ``iterations=4`` is one Gaussian and three joint passes.
Structures smaller than ``sigma_spatial`` vanish in ``J^1`` and never come back; large edges,
only blurred by ``J^1``, are sharpened again by each pass.

Depth: ``q`` runs over the disk ``|q - p| <= radius`` and only over pixels where ``I`` has a depth
(a hole never pulls the result toward 0). The iterates are defined at holes too (from the depth
around them), so ``fill_holes=True`` returns them there; by default holes stay holes.
``depth_adaptive=True`` uses ``sigma_color(p) = sigma_color * (J^t(p) / z_ref)^2``.

Difference from OpenCV: ``cv2.ximgproc.rollingGuidanceFilter`` initialises its guidance with the
input itself, so its first pass is a *bilateral* filter of I (which keeps small high-contrast
structures) instead of the Gaussian of eq. 10; see ``tests/methods/test_rolling_guidance.py``.
"""
from __future__ import annotations

import numpy as np

from methods._defaults import shared_help, swept
from methods._kernels import gaussian_mean, joint_mean
from methods.base import Denoiser, check_depth, check_flag, check_iterations, check_radius, check_sigma

from methods.bilateral import Z_REF_M, range_coefficient

NAME = "rolling_guidance"


def _resolve(sigma_spatial, sigma_color, iterations, radius, fill_holes, depth_adaptive, z_ref):
    d = swept(NAME)
    sigma_spatial = check_sigma(d["sigma_spatial"] if sigma_spatial is None else sigma_spatial, "sigma_spatial",
                                method=NAME, unit="pixels")
    sigma_color = check_sigma(d["sigma_color"] if sigma_color is None else sigma_color, "sigma_color",
                              method=NAME, unit="metres", allow_inf=True)
    iterations = check_iterations(d["iterations"] if iterations is None else iterations, method=NAME)
    radius = check_radius(radius, sigma_spatial, method=NAME)
    fill_holes = check_flag(fill_holes, "fill_holes", method=NAME)
    depth_adaptive = check_flag(d.get("depth_adaptive", False) if depth_adaptive is None else depth_adaptive,
                                "depth_adaptive", method=NAME)
    z_ref = check_sigma(Z_REF_M if z_ref is None else z_ref, "z_ref", method=NAME, unit="metres")
    return sigma_spatial, sigma_color, iterations, radius, fill_holes, depth_adaptive, z_ref


def rolling_guidance_filter(depth: np.ndarray, *, sigma_spatial: float | None = None,
                            sigma_color: float | None = None, iterations: int | None = None,
                            radius: int | None = None, fill_holes: bool = False, depth_adaptive: bool | None = None,
                            z_ref: float | None = None) -> np.ndarray:
    """Hole-aware Rolling Guidance Filter of a depth map (eq. 10, then eq. 11 repeated).

    Args:
        depth: ``(H, W)`` float32 metres, NaN holes (``I``).
        sigma_spatial: structure scale in pixels (``sigma_s``): smaller structures are removed.
            ``None``: the swept default.
        sigma_color: range width in metres of depth (``sigma_r``); ``None``: the swept default.
        iterations: passes including the Gaussian one (>= 1); ``None``: the swept default.
        radius: disk radius in pixels; ``None``: ``max(1, ceil(2 * sigma_spatial))``.
        fill_holes: return the final iterate at holes too (NaN only where no depth is in reach).
        depth_adaptive: (``None``: the swept default) ``sigma_color(p) = sigma_color * (J^t(p) / z_ref)^2``.
        z_ref: depth in metres where ``sigma_color`` applies when ``depth_adaptive`` (default 2).

    Returns:
        ``(H, W)`` float32 metres ``J^iterations``; NaN where ``depth`` is NaN unless ``fill_holes``.

    Example:
        >>> import numpy as np
        >>> x = np.arange(64)
        >>> row = np.where(x < 32, 1.0, 2.0) + 0.05 * (x % 4 == 0)       # a step plus 1-pixel bumps
        >>> depth = np.tile(row, (16, 1)).astype(np.float32)
        >>> out = rolling_guidance_filter(depth, sigma_spatial=3.0, sigma_color=0.1, iterations=4)
        >>> bool(abs(out[8, 10] - 1.0125) < 2e-3), bool(out[8, 40] - out[8, 24] > 0.99)
        (True, True)
    """
    depth = check_depth(depth)
    sigma_spatial, sigma_color, iterations, radius, fill_holes, depth_adaptive, z_ref = _resolve(
        sigma_spatial, sigma_color, iterations, radius, fill_holes, depth_adaptive, z_ref)
    J = gaussian_mean(depth, sigma_spatial=sigma_spatial, radius=radius)          # J^1, eq. 10
    for _ in range(iterations - 1):                                                 # eq. 11
        coef = range_coefficient(J, sigma_color, depth_adaptive=depth_adaptive, z_ref=z_ref)
        J = joint_mean(depth, J, coef, sigma_spatial=sigma_spatial, radius=radius, ref=J)
    if not fill_holes:
        J[~np.isfinite(depth)] = np.nan
    return J


class RollingGuidanceFilter(Denoiser):
    """Rolling Guidance Filter of Zhang et al.; see :func:`rolling_guidance_filter`."""

    name = NAME
    version = "1"
    description = "rolling guidance filter (Zhang et al., eq. 9-11): Gaussian, then joint bilateral of I by J^t"
    defaults = {"sigma_spatial": None, "sigma_color": None, "iterations": None, "radius": None, "fill_holes": False,
                "depth_adaptive": False, "z_ref": Z_REF_M, **swept(NAME)}   # order of listing, swept values
    param_help = {
        "sigma_spatial": "structure scale, pixels: smaller structures are removed (eq. 9-11)",
        "sigma_color": "range width on the guide J^t, metres of depth (eq. 11)",
        "iterations": "passes including the first Gaussian one",
        **shared_help("radius"),
        "fill_holes": "true: holes get the final iterate (the filter's own estimate there)",
        **shared_help("depth_adaptive", "z_ref"),
    }

    def check_params(self, params):
        _resolve(**params)

    def _denoise(self, depth, color, camera):
        return rolling_guidance_filter(depth, **self.params)
