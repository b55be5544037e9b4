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
    count = np.isfinite(stack).sum(axis=0)
    with np.errstate(invalid="ignore"), _quiet():
        bg = np.nanpercentile(stack, percentile, axis=0).astype(np.float32)
    bg[count < min_count] = np.nan
    return bg


class _quiet:
    def __enter__(self):
        import warnings

        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter("ignore", RuntimeWarning)

    def __exit__(self, *exc):
        self._w.__exit__(*exc)


def foreground_mask(depth: np.ndarray, background: np.ndarray, *, margin_m: float = 0.15, margin_rel: float = 0.05,
                    min_area_px: int = 100, open_px: int = 1) -> np.ndarray:
    """M_r: ``(H, W)`` bool, pixels at least ``max(margin_m, margin_rel * background)`` in front of the background.

    Pixels without depth, or without a background estimate, are not foreground.
    """
    d = np.asarray(depth, np.float32)
    bg = np.asarray(background, np.float32)
    if d.shape != bg.shape:
        raise ShapeError(f"depth {d.shape} and background {bg.shape} differ in shape")
    with np.errstate(invalid="ignore"):
        fg = (d > 0) & (d < bg - np.maximum(margin_m, margin_rel * bg))
    m = fg.astype(np.uint8)
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
