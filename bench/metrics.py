"""Depth-denoising metrics: pure numpy (and scipy's KD-tree), no I/O.

Every metric compares a prediction (the denoised LQ depth) with a reference (the HQ depth warped
onto the LQ image, or the simulator's noise-free truth). Depths are ``(H, W)`` float arrays in
metres with NaN for "no measurement"; errors are reported in millimetres.

Pixel sets (the same for every metric; :mod:`bench.masks`):

* ``R`` - reference pixels: reference finite (and > 0), inside the ROI mask when one is given;
* ``M`` - scored pixels: ``R`` and the prediction finite (and > 0). Every error metric is a mean over
  ``M``; :func:`fill_rate` is ``|M| / |R|``, so a method cannot win by deleting hard pixels.

Plane-fit RMSE (Sterzentsenko et al., DDD; seed report section IV): the RMSE over scored points of
the distance from each point's closest denoised point to the least-squares plane of its reference
neighbourhood; defined, and computed exactly, in :mod:`bench.plane_fit` (re-exported here).

Normal angle: the mean angle between central-difference normals of prediction and reference.

Moving stratum (:func:`moving_mask`): the pixels of ``M`` whose scene depth changed by more than
``MetricConfig.moving_threshold_m`` (1 cm) since the previous frame, from the simulator's truth
where the dataset has one, else from the reference; ``mse_moving_mm2`` / ``mae_moving_mm`` are the
errors over them (SSDD's level 2 is meant to win on moving content). The first frame of a sequence
has no previous frame: its moving metrics are NaN.

:func:`frame_metrics` gives every metric of one frame, overall and per reference-depth bin.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from bench.errors import MetricInputError
from bench.masks import check_pair, finite_positive, reference_mask, valid_mask  # noqa: F401 (re-exported)
from bench.plane_fit import (PLANE_FIT_METHODS, PlaneFitResult, ReferencePlanes,  # noqa: F401 (re-exported)
                             check_plane_parameters, fit_reference_planes, plane_fit_rmse, smallest_eigh3)
from bench.plane_search import rays
from capture.camera import Intrinsics

#: Frame-level metrics in the results table, with their units.
UNITS = {
    "n_reference": "count", "n_valid": "count", "fill_rate": "ratio",
    "mse_mm2": "mm^2", "rmse_mm": "mm", "mae_mm": "mm", "bias_mm": "mm",
    "plane_fit_rmse_mm": "mm", "plane_fit_n": "count", "plane_fit_excluded_few": "count",
    "plane_fit_excluded_degenerate": "count", "plane_fit_excluded": "count",
    "plane_fit_neighbors_median": "count", "normal_angle_deg": "deg",
    "n_moving": "count", "mse_moving_mm2": "mm^2", "mae_moving_mm": "mm",
}
#: Metrics also given per reference-depth bin.
BINNED = ("n_valid", "mae_mm", "rmse_mm", "plane_fit_n", "plane_fit_rmse_mm", "plane_fit_excluded")


@dataclass(frozen=True)
class MetricConfig:
    """Parameters of the metrics; part of a results folder's identity.

    Attributes:
        radius_m: plane-fit neighbourhood radius in metres (DDD: 5 mm).
        min_neighbors: fewest reference points (the point itself included) for a plane.
        min_spread_ratio: a neighbourhood whose second-largest standard deviation is below this
            fraction of its largest is a line, not a plane, and is excluded.
        depth_bin_m: width of the reference-depth bins of the error-against-depth rows.
        moving_threshold_m: a pixel is "moving" when its depth changed by more than this since the
            previous frame (:func:`moving_mask`).
    """

    radius_m: float = 0.005
    min_neighbors: int = 3
    min_spread_ratio: float = 0.1
    depth_bin_m: float = 0.25
    moving_threshold_m: float = 0.01

    def __post_init__(self) -> None:
        check_plane_parameters(radius_m=self.radius_m, min_neighbors=self.min_neighbors,
                               min_spread_ratio=self.min_spread_ratio)
        if not (np.isfinite(self.depth_bin_m) and self.depth_bin_m > 0):
            raise MetricInputError(f"depth_bin_m must be positive, got {self.depth_bin_m}")
        if not (np.isfinite(self.moving_threshold_m) and self.moving_threshold_m >= 0):
            raise MetricInputError(f"moving_threshold_m must be non-negative, got {self.moving_threshold_m}")

    def to_dict(self) -> dict:
        return {k: (int(v) if k == "min_neighbors" else float(v)) for k, v in asdict(self).items()}


# --------------------------------------------------------------------------------- pixel errors
def pixel_errors(pred: np.ndarray, ref: np.ndarray, roi: np.ndarray | None = None) -> dict[str, float]:
    """MSE (mm^2), RMSE, MAE and mean signed error ``pred - ref`` (mm) over pixels ``M``.

    Returns a dict with ``mse_mm2, rmse_mm, mae_mm, bias_mm, n_valid`` (NaN errors when ``M`` is empty).
    """
    m = valid_mask(pred, ref, roi)
    e = (pred[m].astype(np.float64) - ref[m].astype(np.float64)) * 1000.0
    if e.size == 0:
        return {"mse_mm2": np.nan, "rmse_mm": np.nan, "mae_mm": np.nan, "bias_mm": np.nan, "n_valid": 0}
    mse = float(np.mean(e * e))
    return {"mse_mm2": mse, "rmse_mm": float(np.sqrt(mse)), "mae_mm": float(np.mean(np.abs(e))),
            "bias_mm": float(np.mean(e)), "n_valid": int(e.size)}


def mse_mm2(pred, ref, roi=None) -> float:
    """Mean squared error in mm^2 over pixels valid in both (inside ``roi``)."""
    return pixel_errors(pred, ref, roi)["mse_mm2"]


def rmse_mm(pred, ref, roi=None) -> float:
    """Root mean squared error in mm over pixels valid in both (inside ``roi``)."""
    return pixel_errors(pred, ref, roi)["rmse_mm"]


def mae_mm(pred, ref, roi=None) -> float:
    """Mean absolute error in mm over pixels valid in both (inside ``roi``)."""
    return pixel_errors(pred, ref, roi)["mae_mm"]


def moving_mask(depth: np.ndarray, previous: np.ndarray, *, threshold_m: float) -> np.ndarray:
    """``(H, W)`` bool: pixels whose depth changed by more than ``threshold_m`` metres since ``previous``,
    ``|depth - previous| > threshold_m``, where both hold a measurement (a pixel that appears or vanishes
    is not counted: in a reference that is mostly hole flicker)."""
    if depth.shape != previous.shape:
        raise MetricInputError(f"depth {depth.shape} and previous depth {previous.shape} must have the same size")
    with np.errstate(invalid="ignore"):
        change = np.abs(depth.astype(np.float64) - previous.astype(np.float64))
    return finite_positive(depth) & finite_positive(previous) & (change > threshold_m)


def moving_errors(pred: np.ndarray, ref: np.ndarray, moving: np.ndarray | None,
                  roi: np.ndarray | None = None) -> dict[str, float]:
    """``n_moving``, ``mse_moving_mm2``, ``mae_moving_mm``: :func:`pixel_errors` over the pixels ``M`` that
    are in ``moving`` (:func:`moving_mask`); all NaN when ``moving`` is None (no previous frame)."""
    if moving is None:
        return {"n_moving": np.nan, "mse_moving_mm2": np.nan, "mae_moving_mm": np.nan}
    pe = pixel_errors(pred, ref, moving if roi is None else moving & roi.astype(bool))
    return {"n_moving": float(pe["n_valid"]), "mse_moving_mm2": pe["mse_mm2"], "mae_moving_mm": pe["mae_mm"]}


def fill_rate(pred: np.ndarray, ref: np.ndarray, roi: np.ndarray | None = None) -> float:
    """Share of reference-valid ROI pixels that the prediction leaves valid, ``|M| / |R|`` (NaN if ``R`` is empty)."""
    n_ref = int(np.count_nonzero(reference_mask(ref, roi)))
    return float(np.count_nonzero(valid_mask(pred, ref, roi)) / n_ref) if n_ref else float("nan")


# --------------------------------------------------------------------------------- normals
def _normal_components(depth: np.ndarray, intrinsics: Intrinsics,
                       box: tuple[slice, slice] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The three components of :func:`normal_map` as ``(H, W)`` arrays (NaN where undefined), or of
    the window ``box`` of the image only (its border pixels then have no normal)."""
    if depth.shape != intrinsics.shape:
        raise MetricInputError(f"depth has shape {depth.shape}, intrinsics are {intrinsics.width}x{intrinsics.height}")
    xn, yn, _ = rays(intrinsics)
    if box is not None:
        depth, xn, yn = depth[box], xn[box], yn[box]
    z = np.where(finite_positive(depth), depth, np.nan).astype(np.float64)
    x, y = xn * z, yn * z
    c = (slice(1, -1), slice(1, -1))
    l, r, u, d = (slice(1, -1), slice(None, -2)), (slice(1, -1), slice(2, None)), \
        (slice(None, -2), slice(1, -1)), (slice(2, None), slice(1, -1))
    ax, ay, az = x[r] - x[l], y[r] - y[l], z[r] - z[l]          # along u
    bx, by, bz = x[d] - x[u], y[d] - y[u], z[d] - z[u]          # along v
    cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    with np.errstate(invalid="ignore", divide="ignore"):
        inv = 1.0 / np.sqrt(cx * cx + cy * cy + cz * cz)
        inv = np.where(cz > 0, -inv, inv)                        # towards the camera
        inv[~np.isfinite(z[c]) | ~np.isfinite(inv)] = np.nan
    out = []
    for comp in (cx, cy, cz):
        full = np.full(depth.shape, np.nan)
        full[c] = comp * inv
        out.append(full)
    return out[0], out[1], out[2]


def _grown_box(mask: np.ndarray, grow: int = 1) -> tuple[slice, slice]:
    """Bounding box of ``mask`` grown by ``grow`` pixels (the whole image when the mask is empty)."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return slice(0, mask.shape[0]), slice(0, mask.shape[1])
    return (slice(max(rows[0] - grow, 0), min(rows[-1] + grow + 1, mask.shape[0])),
            slice(max(cols[0] - grow, 0), min(cols[-1] + grow + 1, mask.shape[1])))


def normal_map(depth: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """Surface normals of a depth image from central differences of its point cloud.

    ``n(u, v) = normalise((P[v, u+1] - P[v, u-1]) x (P[v+1, u] - P[v-1, u]))``, oriented towards the
    camera (``n_z < 0``). Returns ``(H, W, 3)`` float64, NaN where a neighbour or the pixel is invalid
    and on the image border.
    """
    return np.stack(_normal_components(depth, intrinsics), axis=-1)


def normal_angle_deg(pred: np.ndarray, ref: np.ndarray, intrinsics: Intrinsics, roi: np.ndarray | None = None, *,
                     ref_normals: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> float:
    """Mean angle in degrees between the :func:`normal_map` normals of prediction and reference.

    Over pixels ``M`` where both normals are defined; NaN when there are none. ``ref_normals``:
    the reference's normal components (``_normal_components(ref, intrinsics)``) when the caller has them.
    """
    m = valid_mask(pred, ref, roi)
    if not m.any():
        return float("nan")
    box = _grown_box(reference_mask(ref, roi))
    if ref_normals is None or ref_normals[0].shape != (box[0].stop - box[0].start, box[1].stop - box[1].start):
        ref_normals = _normal_components(ref, intrinsics, box)
    a = _normal_components(pred, intrinsics, box)
    m = m[box]
    cos = a[0][m] * ref_normals[0][m] + a[1][m] * ref_normals[1][m] + a[2][m] * ref_normals[2][m]
    cos = cos[np.isfinite(cos)]
    if cos.size == 0:
        return float("nan")
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).mean())


# --------------------------------------------------------------------------------- one frame
def frame_metrics(pred: np.ndarray, ref: np.ndarray, intrinsics: Intrinsics, *, roi: np.ndarray | None = None,
                  config: MetricConfig = MetricConfig(), planes: ReferencePlanes | None = None,
                  plane_fit_method: str = "auto", threads: int = 1, moving: np.ndarray | None = None) -> tuple[dict[str, float], list[dict[str, float]]]:
    """Every metric of one frame against one reference.

    Args:
        pred, ref: ``(H, W)`` depth in metres, NaN = none.
        intrinsics: the LQ camera.
        roi: optional ``(H, W)`` bool region of interest.
        config: metric parameters.
        planes: :func:`fit_reference_planes` of ``ref``/``roi`` with ``config`` (reused across methods).
        plane_fit_method: ``"auto"``, ``"grid"`` or ``"kdtree"`` (equal results).
        threads: threads for the plane fit (results do not depend on it).
        moving: ``(H, W)`` bool :func:`moving_mask` of the frame (None: no previous frame, moving metrics NaN).

    Returns:
        ``(metrics, bins)``: ``metrics`` maps every name of :data:`UNITS` to a float; ``bins`` lists
        ``{"bin_lo_m", "bin_hi_m", <every name of BINNED>}`` for the reference-depth bins of width
        ``config.depth_bin_m`` that hold at least one reference pixel.
    """
    check_pair(pred, ref, roi)
    if planes is None:
        planes = fit_reference_planes(ref, intrinsics, roi=roi, radius_m=config.radius_m,
                                      min_neighbors=config.min_neighbors, min_spread_ratio=config.min_spread_ratio,
                                      method=plane_fit_method, threads=threads)
    R = planes.mask
    M = R & finite_positive(pred)
    out = {"n_reference": float(np.count_nonzero(R))}
    pe = pixel_errors(pred, ref, roi)
    out["n_valid"] = float(pe.pop("n_valid"))
    out["fill_rate"] = out["n_valid"] / out["n_reference"] if out["n_reference"] else float("nan")
    out.update(pe)
    out.update(moving_errors(pred, ref, moving, roi))
    pf = plane_fit_rmse(pred, ref, intrinsics, roi=roi, planes=planes, threads=threads)
    out["plane_fit_rmse_mm"] = pf.rmse_mm
    out["plane_fit_n"] = float(pf.n_used)
    out["plane_fit_excluded_few"] = float(pf.n_excluded_few)
    out["plane_fit_excluded_degenerate"] = float(pf.n_excluded_degenerate)
    out["plane_fit_excluded"] = out["plane_fit_excluded_few"] + out["plane_fit_excluded_degenerate"]
    out["plane_fit_neighbors_median"] = float(np.median(pf.neighbors[M])) if M.any() else float("nan")
    if planes.pixel_normals is None and R.any():
        planes.pixel_normals = _normal_components(ref, intrinsics, _grown_box(R))
    out["normal_angle_deg"] = normal_angle_deg(pred, ref, intrinsics, roi, ref_normals=planes.pixel_normals)

    bins: list[dict[str, float]] = []
    if R.any():
        w = config.depth_bin_m
        b_ref = np.floor(ref[R].astype(np.float64) / w).astype(np.int64)
        lo = int(b_ref.min())
        present = np.flatnonzero(np.bincount(b_ref - lo)) + lo
        b = np.floor(ref[M].astype(np.float64) / w).astype(np.int64) - lo
        nb = len(np.bincount(b_ref - lo))
        e = (pred[M].astype(np.float64) - ref[M].astype(np.float64)) * 1000.0
        st, dist = pf.status[M], pf.distance_m[M] * 1000.0
        used = st == 1
        n_valid = np.bincount(b, minlength=nb).astype(np.float64)
        abs_sum = np.bincount(b, weights=np.abs(e), minlength=nb)
        sq_sum = np.bincount(b, weights=e * e, minlength=nb)
        pf_n = np.bincount(b[used], minlength=nb).astype(np.float64)
        pf_sq = np.bincount(b[used], weights=dist[used] ** 2, minlength=nb)
        pf_ex = np.bincount(b[st >= 2], minlength=nb).astype(np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            mae, rmse, pf_rmse = abs_sum / n_valid, np.sqrt(sq_sum / n_valid), np.sqrt(pf_sq / pf_n)
        for k in present - lo:
            bins.append({"bin_lo_m": round((k + lo) * w, 9), "bin_hi_m": round((k + lo + 1) * w, 9),
                         "n_valid": float(n_valid[k]), "mae_mm": float(mae[k]), "rmse_mm": float(rmse[k]),
                         "plane_fit_n": float(pf_n[k]), "plane_fit_rmse_mm": float(pf_rmse[k]),
                         "plane_fit_excluded": float(pf_ex[k])})
    return out, bins
