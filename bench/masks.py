"""The pixel sets every metric is a mean over: pure numpy, no I/O.

Depths are ``(H, W)`` float arrays in metres with NaN (or 0) for "no measurement":

* ``R`` (:func:`reference_mask`) - reference pixels: reference finite and > 0, inside the ROI
  mask when one is given;
* ``M`` (:func:`valid_mask`) - scored pixels: ``R`` and the prediction finite and > 0.
"""
from __future__ import annotations

import numpy as np

from bench.errors import MetricInputError


def finite_positive(depth: np.ndarray) -> np.ndarray:
    """``(H, W)`` bool: the pixels holding a measurement (finite and > 0)."""
    with np.errstate(invalid="ignore"):
        return np.isfinite(depth) & (depth > 0)


def check_pair(pred: np.ndarray, ref: np.ndarray, roi: np.ndarray | None) -> None:
    """Raise :class:`MetricInputError` unless prediction, reference and ROI are ``(H, W)`` of one size."""
    if pred.ndim != 2 or pred.shape != ref.shape:
        raise MetricInputError(f"prediction {pred.shape} and reference {ref.shape} must be (H, W) of the same size")
    if roi is not None and roi.shape != ref.shape:
        raise MetricInputError(f"ROI mask {roi.shape} must have the reference's shape {ref.shape}")


def reference_mask(ref: np.ndarray, roi: np.ndarray | None = None) -> np.ndarray:
    """Pixels ``R``: reference valid, inside ``roi`` when given. ``(H, W)`` bool."""
    m = finite_positive(ref)
    return m & roi.astype(bool) if roi is not None else m


def valid_mask(pred: np.ndarray, ref: np.ndarray, roi: np.ndarray | None = None) -> np.ndarray:
    """Pixels ``M``: valid in both prediction and reference, inside ``roi``. ``(H, W)`` bool."""
    check_pair(pred, ref, roi)
    return reference_mask(ref, roi) & finite_positive(pred)
