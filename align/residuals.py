"""Residual statistics of an alignment: per pair and over the dataset. Pure numpy, no I/O.

Two residuals are used:

* the feature residual, eq. 31 per pair ``||pi_LQ(T_ex X) - p_LQ||`` in pixels (from the fit);
* the depth residual of a pair, ``|D_LQ - D~_HQ| / D~_HQ`` (relative, so near and far pixels
  weigh alike) summarised by its median over the pixels where both have depth. A pair whose
  frames are badly aligned (wrong time, a glitch) stands out against the other pairs.
"""
from __future__ import annotations

import numpy as np


def robust_summary(x) -> dict:
    """n, mean, median, MAD-based sigma, 90th/99th percentile and RMS of the finite values of ``x``."""
    v = np.asarray(x, np.float64).ravel()
    v = v[np.isfinite(v)]
    if v.size == 0:
        return {"n": 0}
    med = float(np.median(v))
    return {"n": int(v.size), "mean": float(v.mean()), "median": med,
            "sigma_mad": float(1.4826 * np.median(np.abs(v - med))), "p90": float(np.percentile(v, 90)),
            "p99": float(np.percentile(v, 99)), "rms": float(np.sqrt(np.mean(v ** 2)))}


def depth_residual(lq_depth: np.ndarray, reference: np.ndarray, *, min_pixels: int = 100) -> tuple[float, int]:
    """Median relative difference between LQ depth and the warped HQ depth, and how many pixels it used.

    NaN when fewer than ``min_pixels`` pixels have both.
    """
    both = np.isfinite(lq_depth) & np.isfinite(reference) & (reference > 0)
    n = int(both.sum())
    if n < min_pixels:
        return float("nan"), n
    return float(np.median(np.abs(lq_depth[both] - reference[both]) / reference[both])), n


def outliers(values, *, k: float = 5.0, floor: float = 0.0) -> np.ndarray:
    """``values`` above ``median + max(k * sigma_MAD, floor)``; NaN counts as an outlier."""
    v = np.asarray(values, np.float64)
    fin = np.isfinite(v)
    if not fin.any():
        return ~fin
    med = np.median(v[fin])
    sig = 1.4826 * np.median(np.abs(v[fin] - med))
    return ~fin | (v > med + max(k * sig, floor))
