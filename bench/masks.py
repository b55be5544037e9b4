"""The pixel sets every metric is a mean over: pure numpy, no I/O.

Depths are ``(H, W)`` float arrays in metres with NaN (or 0) for "no measurement":

* ``R`` (:func:`reference_mask`) - reference pixels: reference finite and > 0, inside the ROI
  mask when one is given;
* ``M`` (:func:`valid_mask`) - scored pixels: ``R`` and the prediction finite and > 0.

Against the simulator's truth (:func:`truth_strata`) the pixels are split by the HQ reference, so that
the truth columns score what the reference columns score (like with like):

* ``"truth"`` - the truth on the pixels where the HQ reference has depth: with the ROI, exactly the
  reference's ``R``;
* ``"truth_noref"`` - the truth on the ROI pixels **without** a reference ("silhouettes / no reference":
  HQ sensor holes along silhouettes, the gap past a surface's last HQ sample, occlusion shadows, the
  edge rule's mask). The reference scores none of them; only the truth does.
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


#: the truth strata of :func:`truth_strata`: reference name in the results table -> what it scores
TRUTH_STRATA = {"truth": "truth on the HQ reference's pixels",
                "truth_noref": "truth on the ROI pixels without an HQ reference (silhouettes / no reference)"}


def truth_strata(truth: np.ndarray, reference: np.ndarray) -> dict[str, np.ndarray]:
    """The truth ``(H, W)`` float metres split by the reference ``(H, W)``: ``{"truth": truth where the
    reference holds a measurement, else NaN, "truth_noref": truth where it holds none, else NaN}``
    (:data:`TRUTH_STRATA`). Scored inside the ROI (:func:`reference_mask`), the first's pixels are the
    reference's ``R`` (where the truth has depth) and the second's ``ROI & ~R``.

    Example:
        >>> t = np.array([[1.0, 2.0, 3.0]], np.float32); r = np.array([[1.1, np.nan, 0.0]], np.float32)
        >>> {k: v.tolist() for k, v in truth_strata(t, r).items()}
        {'truth': [[1.0, nan, nan]], 'truth_noref': [[nan, 2.0, 3.0]]}
    """
    if truth.shape != reference.shape:
        raise MetricInputError(f"truth {truth.shape} and reference {reference.shape} must have the same size")
    has = finite_positive(reference)
    none = np.array(np.nan, dtype=truth.dtype)
    return {"truth": np.where(has, truth, none), "truth_noref": np.where(has, none, truth)}


def valid_mask(pred: np.ndarray, ref: np.ndarray, roi: np.ndarray | None = None) -> np.ndarray:
    """Pixels ``M``: valid in both prediction and reference, inside ``roi``. ``(H, W)`` bool."""
    check_pair(pred, ref, roi)
    return reference_mask(ref, roi) & finite_positive(pred)
