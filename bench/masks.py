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

Away from the reference's depth edges (:func:`depth_edge_mask`, :func:`interior_strata`): ``"hq_interior"`` and
``"truth_interior"`` score ``R`` less the pixels within ``EDGE_WIDTH_PX`` of a depth jump of the reference
itself (its holes filled from their farthest neighbour first, so that a silhouette whose far side the edge rule
masked is still an edge). Only the reference decides which pixels these are, so the stratum exists on real
captures too. Why it exists: at a silhouette the reference's last foreground pixels read a mix of the two surfaces
(a time-of-flight pixel integrates its footprint; the warp interpolates), and so do the outputs of methods that
regress across the edge (a CNN's), so there the reference's error and those methods' errors are correlated and the
reference favours them. On the demo session (issue 12, session 13) the reference's pixels within 1 px of its
depth edges are 18 % of ``R`` and hold about four fifths of the MSE bias between RGF and SSDD UNet (4.4 mm²,
enough to order that pair against the truth); away from them the reference orders all ten methods as the truth
does, on the demo and seeds 1-2 (where the rule was chosen) and on the held-out seeds 4-9.
"""
from __future__ import annotations

import numpy as np

from bench.errors import MetricInputError

#: a reference pixel is on a depth edge where the depths of its 3 x 3 neighbourhood span more than this share of its
#: own depth (:class:`align.reference_edges.EdgeRule`'s ``edge_rel``)
EDGE_REL = 0.03
#: :func:`depth_edge_mask` keeps the reference pixels within this many pixels (Euclidean) of a depth edge
EDGE_WIDTH_PX = 1.0
#: holes of the reference up to this many pixels from its depth are filled with their farthest neighbour first
EDGE_FILL_PX = 3


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


def depth_edge_mask(reference: np.ndarray, *, width_px: float | None = None, rel: float | None = None,
                    fill_px: int | None = None) -> np.ndarray:
    """``(H, W)`` bool: the reference's pixels (finite and > 0) within ``width_px`` pixels of a depth edge of the
    reference ``(H, W)`` metres.

    The holes of the reference are first filled, ``fill_px`` times over, with the largest depth of their 3 x 3
    neighbours (a silhouette's masked far side takes the background's depth, a dropout inside a surface that
    surface's); a pixel of the filled image is on an edge where its 3 x 3 neighbourhood spans more than ``rel`` of
    its depth. ``None``: ``EDGE_WIDTH_PX``, ``EDGE_REL``, ``EDGE_FILL_PX``.

    Example: a near square on a far wall whose far-side band the reference lacks, and a hole in the wall:
        >>> r = np.full((7, 9), 2.0, np.float32); r[2:5, 2:5] = 1.0; r[:, 5] = np.nan; r[1, 7] = np.nan
        >>> depth_edge_mask(r).astype(int)
        array([[0, 1, 1, 1, 1, 0, 0, 0, 0],
               [1, 1, 1, 1, 1, 0, 1, 0, 0],
               [1, 1, 1, 1, 1, 0, 1, 0, 0],
               [1, 1, 1, 1, 1, 0, 1, 0, 0],
               [1, 1, 1, 1, 1, 0, 1, 0, 0],
               [1, 1, 1, 1, 1, 0, 1, 0, 0],
               [0, 1, 1, 1, 1, 0, 0, 0, 0]])

    The square and the ring of wall around it are within 1 px of a jump; so is the wall's first column past the
    missing band (its filled neighbours hold the jump); the isolated hole is filled from the wall and is no edge.
    """
    import cv2

    width = EDGE_WIDTH_PX if width_px is None else float(width_px)
    rel = EDGE_REL if rel is None else float(rel)
    fill = EDGE_FILL_PX if fill_px is None else int(fill_px)
    if reference.ndim != 2 or width < 0 or rel <= 0 or fill < 0:
        raise MetricInputError(f"depth edges need an (H, W) reference, width_px >= 0, rel > 0 and fill_px >= 0; got "
                               f"{reference.shape}, {width_px!r}, {rel!r}, {fill_px!r}")
    has = finite_positive(reference)
    d = np.where(has, reference, 0).astype(np.float32)
    k = np.ones((3, 3), np.uint8)
    for _ in range(fill):
        d = np.where(d > 0, d, cv2.dilate(d, k))
    hi = cv2.dilate(d, k)
    lo = cv2.erode(np.where(d > 0, d, np.float32(np.inf)), k)
    edge = (d > 0) & (hi - lo > rel * d)
    if not edge.any():
        return np.zeros(reference.shape, bool)
    dist = cv2.distanceTransform((~edge).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return has & (dist <= width + 1e-6)


def interior_strata(reference: np.ndarray, truth: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The reference ``(H, W)`` metres away from its own depth edges (:func:`depth_edge_mask`, NaN on them), and
    the truth ``(H, W)`` on the same pixels when given: ``{"hq_interior": ..., "truth_interior": ...}``.

    >>> r = np.full((5, 5), 2.0, np.float32); r[:, 3:] = 1.0; t = r + np.float32(0.01)
    >>> {k: np.isfinite(v).sum(axis=0).tolist() for k, v in interior_strata(r, t).items()}
    {'hq_interior': [5, 0, 0, 0, 0], 'truth_interior': [5, 0, 0, 0, 0]}
    """
    none = np.array(np.nan, dtype=reference.dtype)
    keep = finite_positive(reference) & ~depth_edge_mask(reference)
    out = {"hq_interior": np.where(keep, reference, none)}
    if truth is not None:
        if truth.shape != reference.shape:
            raise MetricInputError(f"truth {truth.shape} and reference {reference.shape} must have the same size")
        out["truth_interior"] = np.where(keep, truth, np.array(np.nan, dtype=truth.dtype))
    return out
