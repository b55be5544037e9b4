"""Hole-aware bilateral filter on depth (Tomasi and Manduchi 1998; seed report eq. 5-8).

For every pixel ``p`` with a depth ``f(p)``::

    h(p) = 1/k(p) * sum_q c(q, p) s(f(q), f(p)) f(q)                                   (eq. 5)
    k(p) =          sum_q c(q, p) s(f(q), f(p))                                        (eq. 6)
    c(q, p) = exp(-|q - p|^2 / (2 sigma_spatial^2))                                    (eq. 7)
    s(f(q), f(p)) = exp(-(f(q) - f(p))^2 / (2 sigma_color(p)^2))                       (eq. 8)

where ``q`` runs over the disk ``|q - p| <= radius`` **and only over pixels with a depth**: a hole
is left out of both sums (it never counts as depth 0), and so is everything outside the image.
A hole stays a hole unless ``fill_holes=True``; it then gets the normalised spatial Gaussian of the
valid depths in its window (eq. 1-2 over valid pixels: there is no centre depth for eq. 8 to
compare with; at an object boundary that value lies between the two surfaces).

``depth_adaptive=True`` widens the range kernel with distance, for sensors whose noise grows like
``z^2`` (stereo: ``sigma_z = z^2 sigma_d / (f b)``)::

    sigma_color(p) = sigma_color * (f(p) / z_ref)^2

so ``sigma_color`` is the range width at ``z_ref`` metres (default 2 m, the middle of 1-3 m).
"""
from __future__ import annotations

import numpy as np

from methods._defaults import shared_help, swept
from methods._kernels import joint_mean
from methods.base import Denoiser, check_depth, check_flag, check_radius, check_sigma

NAME = "bilateral"
Z_REF_M = 2.0


def _resolve(sigma_spatial, sigma_color, radius, fill_holes, depth_adaptive, z_ref):
    d = swept(NAME)
    sigma_spatial = check_sigma(d["sigma_spatial"] if sigma_spatial is None else sigma_spatial, "sigma_spatial",
                                method=NAME, unit="pixels")
    sigma_color = check_sigma(d["sigma_color"] if sigma_color is None else sigma_color, "sigma_color",
                              method=NAME, unit="metres", allow_inf=True)
    radius = check_radius(radius, sigma_spatial, method=NAME)
    fill_holes = check_flag(fill_holes, "fill_holes", method=NAME)
    depth_adaptive = check_flag(d.get("depth_adaptive", False) if depth_adaptive is None else depth_adaptive,
                                "depth_adaptive", method=NAME)
    z_ref = check_sigma(Z_REF_M if z_ref is None else z_ref, "z_ref", method=NAME, unit="metres")
    return sigma_spatial, sigma_color, radius, fill_holes, depth_adaptive, z_ref


def range_coefficient(z: np.ndarray, sigma_color: float, *, depth_adaptive: bool, z_ref: float) -> np.ndarray:
    """``1 / (2 sigma_color(z)^2)`` per pixel (eq. 8), with the optional ``(z / z_ref)^2`` growth."""
    if not depth_adaptive:
        return np.full(z.shape, 0.5 / sigma_color ** 2, np.float32)
    sigma = sigma_color * (z.astype(np.float64) / z_ref) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        coef = 0.5 / sigma ** 2
    return np.where(np.isfinite(coef), coef, 0.0).astype(np.float32)


def bilateral_filter(depth: np.ndarray, *, sigma_spatial: float | None = None, sigma_color: float | None = None,
                     radius: int | None = None, fill_holes: bool = False, depth_adaptive: bool | None = None,
                     z_ref: float | None = None) -> np.ndarray:
    """Hole-aware bilateral filter of a depth map (eq. 5-8).

    Args:
        depth: ``(H, W)`` float32 metres, NaN where there is no measurement.
        sigma_spatial: spatial Gaussian width in pixels (``sigma_d`` of eq. 7). ``None``: the swept
            default of ``methods/defaults.json``.
        sigma_color: range Gaussian width in metres of depth (``sigma_r`` of eq. 8); ``inf`` turns the
            range kernel off. ``None``: the swept default.
        radius: window radius in pixels; the window is the disk ``dx^2 + dy^2 <= radius^2``.
            ``None``: ``max(1, ceil(2 * sigma_spatial))``.
        fill_holes: give holes the normalised Gaussian of the valid depths around them.
        depth_adaptive: ``sigma_color(z) = sigma_color * (z / z_ref)^2`` with ``z`` the centre depth
            (``None``: the swept default).
        z_ref: the depth in metres at which ``sigma_color`` applies when ``depth_adaptive`` (default 2).

    Returns:
        ``(H, W)`` float32 metres; NaN exactly where ``depth`` is NaN (unless ``fill_holes``: then NaN
        only where the window holds no depth).

    Example:
        >>> import numpy as np
        >>> rng = np.random.default_rng(0)
        >>> depth = (2.0 + 0.01 * rng.standard_normal((48, 64))).astype(np.float32)
        >>> depth[10:14, 10:20] = np.nan
        >>> out = bilateral_filter(depth, sigma_spatial=2.0, sigma_color=0.05)
        >>> out.dtype, bool(np.isnan(out[12, 15])), float(np.nanstd(out)) < float(np.nanstd(depth))
        (dtype('float32'), True, True)
    """
    depth = check_depth(depth)
    sigma_spatial, sigma_color, radius, fill_holes, depth_adaptive, z_ref = _resolve(
        sigma_spatial, sigma_color, radius, fill_holes, depth_adaptive, z_ref)
    valid = np.isfinite(depth)
    coef = range_coefficient(depth, sigma_color, depth_adaptive=depth_adaptive, z_ref=z_ref)
    center = depth
    if fill_holes:  # a hole has no f(p) for eq. 8: spatial weights only (eq. 1-2 over valid pixels)
        center = np.where(valid, depth, np.float32(0.0))
        coef = np.where(valid, coef, np.float32(0.0))
    out = joint_mean(depth, depth, coef, sigma_spatial=sigma_spatial, radius=radius, guide_center=center)
    if not fill_holes:
        out[~valid] = np.nan
    return out


class BilateralFilter(Denoiser):
    """Hole-aware bilateral filter on depth; see :func:`bilateral_filter`."""

    name = NAME
    version = "1"
    description = "bilateral filter (Tomasi & Manduchi, eq. 5-8), hole-aware, range sigma in metres"
    defaults = {"sigma_spatial": None, "sigma_color": None, "radius": None, "fill_holes": False,
                "depth_adaptive": False, "z_ref": Z_REF_M, **swept(NAME)}   # order of listing, swept values
    param_help = {
        "sigma_spatial": "spatial Gaussian width, pixels (eq. 7)",
        "sigma_color": "range Gaussian width, metres of depth (eq. 8); inf = off",
        **shared_help("radius"),
        "fill_holes": "true: holes get the Gaussian mean of the valid depths around them",
        **shared_help("depth_adaptive", "z_ref"),
    }

    def check_params(self, params):
        _resolve(**params)

    def _denoise(self, depth, color, camera):
        return bilateral_filter(depth, **self.params)
