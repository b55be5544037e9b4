"""Region-of-interest mask M_r (eq. 32): the foreground (people, balloons) in front of the background.

Pure numpy/OpenCV, no I/O. SSDD computes its loss only on the human bodies and DDRNet on the
foreground; both find it from depth. With a static rig the background is what the sensor sees
most of the time at each pixel: :func:`background_depth` takes a high percentile of depth over
frames spread through the session, and :func:`foreground_mask` marks pixels clearly in front
of it, then removes specks (opening) and components smaller than ``min_area_px``.
"""
from __future__ import annotations

import cv2
import numpy as np

from align.errors import ShapeError


def background_depth(depths, *, percentile: float = 90.0, min_count: int = 3) -> np.ndarray:
    """Per-pixel background depth ``(H, W)`` float32 metres from frames ``(K, H, W)`` (NaN = none).

    The ``percentile`` of the valid depths over the frames (the far surfaces); NaN where fewer
    than ``min_count`` frames have depth.
    """
    stack = np.asarray(depths, dtype=np.float32)
    if stack.ndim != 3:
        raise ShapeError(f"depths must be (K, H, W), got shape {stack.shape}")
    bg, count = nan_percentile_axis0(stack, percentile)
    bg[count < min_count] = np.nan
    return bg


def nan_percentile_axis0(stack: np.ndarray, percentile: float) -> tuple[np.ndarray, np.ndarray]:
    """``np.nanpercentile(stack, percentile, axis=0)`` (linear interpolation) and the valid counts.

    Vectorised: numpy's own falls back to one Python call per pixel when the stack has NaN
    (half of a demo alignment's time). NaN where a pixel has no valid value.

    >>> s = np.array([[[1.0]], [[np.nan]], [[3.0]], [[2.0]]], np.float32)
    >>> nan_percentile_axis0(s, 50.0)[0].tolist(), nan_percentile_axis0(s, 50.0)[1].tolist()
    ([[2.0]], [[3]])
    """
    ordered = np.sort(stack, axis=0)                      # NaN sort last
    count = np.isfinite(stack).sum(axis=0)
    rank = np.maximum(count - 1, 0) * (percentile / 100.0)
    lo = np.floor(rank).astype(np.intp)
    hi = np.minimum(lo + 1, np.maximum(count - 1, 0))
    v_lo = np.take_along_axis(ordered, lo[None], axis=0)[0].astype(np.float64)
    v_hi = np.take_along_axis(ordered, hi[None], axis=0)[0].astype(np.float64)
    frac = rank - lo
    out = (v_lo + (v_hi - v_lo) * frac).astype(np.float32)
    out[count == 0] = np.nan
    return out, count


def in_front(depth: np.ndarray, background: np.ndarray, *, margin_m: float = 0.15, margin_rel: float = 0.05) -> np.ndarray:
    """Pixels ``(H, W)`` bool whose depth (metres, NaN = none) lies at least ``max(margin_m, margin_rel *
    background)`` in front of the background: :func:`foreground_mask`'s test, before its clean-up."""
    d = np.asarray(depth, np.float32)
    bg = np.asarray(background, np.float32)
    with np.errstate(invalid="ignore"):
        return (d > 0) & (d < bg - np.maximum(margin_m, margin_rel * bg))


def foreground_mask(depth: np.ndarray, background: np.ndarray, *, margin_m: float = 0.15, margin_rel: float = 0.05,
                    min_area_px: int = 100, open_px: int = 1) -> np.ndarray:
    """M_r: ``(H, W)`` bool, pixels at least ``max(margin_m, margin_rel * background)`` in front of the background.

    Pixels without depth, or without a background estimate, are not foreground.
    """
    d = np.asarray(depth, np.float32)
    bg = np.asarray(background, np.float32)
    if d.shape != bg.shape:
        raise ShapeError(f"depth {d.shape} and background {bg.shape} differ in shape")
    m = in_front(d, bg, margin_m=margin_m, margin_rel=margin_rel).astype(np.uint8)
    if open_px > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * open_px + 1, 2 * open_px + 1))
        m = cv2.morphologyEx(m, cv2.MORPH_OPEN, k)
    if min_area_px > 1:
        n, labels, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
        small = np.flatnonzero(stats[:, cv2.CC_STAT_AREA] < min_area_px)
        small = small[small > 0]
        if small.size:
            m[np.isin(labels, small)] = 0
    return m.astype(bool)
