"""Depth-denoising metrics: pure numpy (and scipy's KD-tree), no I/O.

Every metric compares a prediction (the denoised LQ depth) with a reference (the HQ depth warped
onto the LQ image, or the simulator's noise-free truth). Depths are ``(H, W)`` float arrays in
metres with NaN for "no measurement"; errors are reported in millimetres.

Pixel sets (the same for every metric):

* ``R`` - reference pixels: reference finite (and > 0), inside the ROI mask when one is given;
* ``M`` - scored pixels: ``R`` and the prediction finite (and > 0). Every error metric is a mean over
  ``M``; :func:`fill_rate` is ``|M| / |R|``, so a method cannot win by deleting hard pixels.

Plane-fit RMSE (Sterzentsenko et al., DDD; seed report section IV)
-----------------------------------------------------------------
For every reference point ``p`` (pixels ``R``, unprojected with the LQ intrinsics) the least-squares
plane through all reference points within ``radius_m`` of ``p`` (``p`` itself included) is fitted
(total least squares: through the centroid, normal = eigenvector of the smallest eigenvalue of the
neighbourhood covariance). For every scored point (pixels ``M``) the closest point ``q*`` of the
denoised point cloud (prediction finite inside the ROI) is found, and ``|n . (q* - c)|`` is that
point's distance. The metric is the RMSE of these distances over scored points, in mm. When several
denoised points are exactly equally close (frequent with depth quantised to 1 mm), the one with the
lowest row-major pixel index is taken, so every implementation gives the same number.

A point is excluded, and counted, when its neighbourhood has fewer than ``min_neighbors`` points
(``plane_fit_excluded_few``) or does not span a plane (``plane_fit_excluded_degenerate``: the
second-largest spread is below ``min_spread_ratio`` times the largest, e.g. a single row of pixels).

The 5 mm radius on 640x480 depth: one pixel covers ``z / f`` metres, about 1.9 mm at 1 m, 3.7 mm
at 2 m and 5.6 mm at 3 m for f = 537 px. A fronto-parallel surface therefore has about 21
neighbours within 5 mm at 1 m, 5 (the pixel and its 4-neighbours) at 2 m and none beyond
~2.7 m: there every point is excluded and the metric is undefined (NaN, with the exclusion counted).
Slanted surfaces have fewer neighbours still. The report plots the excluded share against depth.
Because the distance is taken to the *closest* denoised point, noise much larger than the pixel
footprint is under-estimated (the closest of many noisy points lies near the plane); the pixel-wise
RMSE/MAE do not have this bias.

Two exact implementations, equal to a per-point brute force (tests):

* ``"grid"`` (organised clouds, no lens distortion): neighbours are searched in the depth image.
  A point ``q`` with ``|q - p| <= d`` lies within ``f * d * sqrt(1 + x_n^2) / (z_p - d)`` pixels of
  ``p`` (``x_n`` the normalised coordinate of ``p``), so a per-pixel window bound makes the search
  exact; neighbourhood sums use shifted-array arithmetic. The closest-point search widens rings
  until a lower bound on every unvisited pixel's distance proves the best one found; pixels whose
  bound exceeds the window cap fall back to the KD-tree.
* ``"kdtree"`` (any cloud): scipy ``cKDTree`` radius pairs and nearest neighbours.

Plane normals come from a vectorised closed-form 3x3 symmetric eigen-solver (trigonometric
eigenvalues, cross-product eigenvector), ~30x faster than batched ``numpy.linalg.eigh``.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
import threading
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache

import numpy as np
from scipy.spatial import cKDTree

from bench.errors import MetricInputError  # noqa: F401 (re-exported)
from capture.camera import Intrinsics

#: Frame-level metrics in the results table, with their units.
UNITS = {
    "n_reference": "count", "n_valid": "count", "fill_rate": "ratio",
    "mse_mm2": "mm^2", "rmse_mm": "mm", "mae_mm": "mm", "bias_mm": "mm",
    "plane_fit_rmse_mm": "mm", "plane_fit_n": "count", "plane_fit_excluded_few": "count",
    "plane_fit_excluded_degenerate": "count", "plane_fit_excluded": "count",
    "plane_fit_neighbors_median": "count", "normal_angle_deg": "deg",
}
#: Metrics also given per reference-depth bin.
BINNED = ("n_valid", "mae_mm", "rmse_mm", "plane_fit_n", "plane_fit_rmse_mm", "plane_fit_excluded")
PLANE_FIT_METHODS = ("auto", "grid", "kdtree")
_GRID_CAP = 8          # widest pixel window (Chebyshev radius) the grid search visits before the KD-tree fallback
_SENTINEL = 1.0e6      # invalid pixels sit at distinct far-away positions (1e6 m apart), never within any radius
_STRIP_ELEMENTS = 16384  # elements per row strip of the grid search (a few arrays of this size stay in L2 cache)


@dataclass(frozen=True)
class MetricConfig:
    """Parameters of the metrics; part of a results folder's identity.

    Attributes:
        radius_m: plane-fit neighbourhood radius in metres (DDD: 5 mm).
        min_neighbors: fewest reference points (the point itself included) for a plane.
        min_spread_ratio: a neighbourhood whose second-largest standard deviation is below this
            fraction of its largest is a line, not a plane, and is excluded.
        depth_bin_m: width of the reference-depth bins of the error-against-depth rows.
    """

    radius_m: float = 0.005
    min_neighbors: int = 3
    min_spread_ratio: float = 0.1
    depth_bin_m: float = 0.25

    def __post_init__(self) -> None:
        if not (np.isfinite(self.radius_m) and self.radius_m > 0):
            raise MetricInputError(f"plane-fit radius must be positive, got {self.radius_m} m")
        if int(self.min_neighbors) != self.min_neighbors or self.min_neighbors < 3:
            raise MetricInputError(f"min_neighbors must be an integer >= 3 (a plane needs 3 points), got {self.min_neighbors}")
        if not 0 <= self.min_spread_ratio < 1:
            raise MetricInputError(f"min_spread_ratio must lie in [0, 1), got {self.min_spread_ratio}")
        if not (np.isfinite(self.depth_bin_m) and self.depth_bin_m > 0):
            raise MetricInputError(f"depth_bin_m must be positive, got {self.depth_bin_m}")

    def to_dict(self) -> dict:
        return {k: (int(v) if k == "min_neighbors" else float(v)) for k, v in asdict(self).items()}


# --------------------------------------------------------------------------------- pixel sets
def _finite_positive(depth: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        return np.isfinite(depth) & (depth > 0)


def _check_pair(pred: np.ndarray, ref: np.ndarray, roi: np.ndarray | None) -> None:
    if pred.ndim != 2 or pred.shape != ref.shape:
        raise MetricInputError(f"prediction {pred.shape} and reference {ref.shape} must be (H, W) of the same size")
    if roi is not None and roi.shape != ref.shape:
        raise MetricInputError(f"ROI mask {roi.shape} must have the reference's shape {ref.shape}")


def reference_mask(ref: np.ndarray, roi: np.ndarray | None = None) -> np.ndarray:
    """Pixels ``R``: reference valid, inside ``roi`` when given. ``(H, W)`` bool."""
    m = _finite_positive(ref)
    return m & roi.astype(bool) if roi is not None else m


def valid_mask(pred: np.ndarray, ref: np.ndarray, roi: np.ndarray | None = None) -> np.ndarray:
    """Pixels ``M``: valid in both prediction and reference, inside ``roi``. ``(H, W)`` bool."""
    _check_pair(pred, ref, roi)
    return reference_mask(ref, roi) & _finite_positive(pred)


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
    xn, yn, _ = _rays(intrinsics)
    if box is not None:
        depth, xn, yn = depth[box], xn[box], yn[box]
    z = np.where(_finite_positive(depth), depth, np.nan).astype(np.float64)
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


# --------------------------------------------------------------------------------- eigen solver
def smallest_eigh3(c00, c01, c02, c11, c12, c22):
    """Eigen-decomposition of many symmetric 3x3 matrices, closed form, vectorised.

    Arguments are the six upper-triangle entries, float64 arrays of shape ``(n,)``. Returns
    ``(lam_min, lam_mid, lam_max, v_min)``, eigenvalues ``(n,)`` in increasing order and ``v_min``
    ``(n, 3)`` the unit eigenvector of the smallest one (NaN where the matrix is a multiple of the
    identity). Eigenvalues by the trigonometric method (Smith 1961); the eigenvector is the longest
    cross product of two rows of ``C - lam_min I``.
    """
    q = (c00 + c11 + c22) / 3.0
    a00, a11, a22 = c00 - q, c11 - q, c22 - q
    p = np.sqrt((a00 * a00 + a11 * a11 + a22 * a22 + 2.0 * (c01 * c01 + c02 * c02 + c12 * c12)) / 6.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        inv = 1.0 / p
        b00, b11, b22, b01, b02, b12 = a00 * inv, a11 * inv, a22 * inv, c01 * inv, c02 * inv, c12 * inv
        det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02)
        phi = np.arccos(np.clip(det * 0.5, -1.0, 1.0)) / 3.0
    lam_max = q + 2.0 * p * np.cos(phi)
    lam_min = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    lam_mid = 3.0 * q - lam_max - lam_min
    # rows of C - lam_min I: r0 = (x0, c01, c02), r1 = (c01, y1, c12), r2 = (c02, c12, z2)
    x0, y1, z2 = c00 - lam_min, c11 - lam_min, c22 - lam_min
    vx, vy, vz = c01 * c12 - c02 * y1, c02 * c01 - x0 * c12, x0 * y1 - c01 * c01          # r0 x r1
    nb = vx * vx + vy * vy + vz * vz
    for cx, cy, cz in ((c01 * z2 - c02 * c12, c02 * c02 - x0 * z2, x0 * c12 - c01 * c02),   # r0 x r2
                       (y1 * z2 - c12 * c12, c12 * c02 - c01 * z2, c01 * c12 - y1 * c02)):  # r1 x r2
        nc = cx * cx + cy * cy + cz * cz
        take = nc > nb
        vx, vy, vz, nb = np.where(take, cx, vx), np.where(take, cy, vy), np.where(take, cz, vz), np.where(take, nc, nb)
    with np.errstate(invalid="ignore", divide="ignore"):
        inv = 1.0 / np.sqrt(nb)
    v = np.empty((nb.size, 3))
    v[:, 0], v[:, 1], v[:, 2] = vx * inv, vy * inv, vz * inv
    return lam_min, lam_mid, lam_max, v


# --------------------------------------------------------------------------------- plane fit
@dataclass
class PlaneFitResult:
    """Per-pixel outcome of :func:`plane_fit_rmse`.

    Attributes:
        rmse_mm: RMSE of the plane distances over used points, mm (NaN when none is used).
        distance_m: ``(H, W)`` plane distance in metres, NaN where the pixel was not used.
        neighbors: ``(H, W)`` int32 neighbourhood size (the point itself included) of every scored pixel, 0 elsewhere.
        status: ``(H, W)`` int8: 0 not scored (outside ``M``), 1 used, 2 too few neighbours,
            3 degenerate (line-like) neighbourhood.
        method: ``"grid"`` or ``"kdtree"``.
    """

    rmse_mm: float
    distance_m: np.ndarray
    neighbors: np.ndarray
    status: np.ndarray
    method: str = "grid"

    @property
    def n_used(self) -> int:
        return int(np.count_nonzero(self.status == 1))

    @property
    def n_excluded_few(self) -> int:
        return int(np.count_nonzero(self.status == 2))

    @property
    def n_excluded_degenerate(self) -> int:
        return int(np.count_nonzero(self.status == 3))


@lru_cache(maxsize=8)
def _rays(intrinsics: Intrinsics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normalised ray coordinates ``xn, yn`` ``(H, W)`` and ``s = sqrt(1 + xn^2 + yn^2)`` (read-only)."""
    rays = intrinsics.ray_grid()
    xn, yn = np.ascontiguousarray(rays[..., 0]), np.ascontiguousarray(rays[..., 1])
    s = np.sqrt(1.0 + xn * xn + yn * yn)
    for a in (xn, yn, s):
        a.setflags(write=False)
    return xn, yn, s


def _ring(k: int) -> list[tuple[int, int]]:
    """Pixel offsets ``(dv, du)`` at Chebyshev distance exactly ``k``."""
    if k == 0:
        return [(0, 0)]
    out = [(dv, du) for dv in (-k, k) for du in range(-k, k + 1)]
    out += [(dv, du) for du in (-k, k) for dv in range(-k + 1, k)]
    return out


def _half_ring(k: int) -> list[tuple[int, int]]:
    """One offset of each opposite pair of :func:`_ring` (``dv > 0``, or ``dv == 0`` and ``du > 0``)."""
    return [(dv, du) for dv, du in _ring(k) if dv > 0 or (dv == 0 and du > 0)]


@lru_cache(maxsize=8)
def _deep_groups(fx: float, fy: float) -> tuple[tuple[float, tuple[tuple[int, int], ...]], ...]:
    """Offsets of Chebyshev distance 2.._GRID_CAP grouped by their normalised length
    ``e = sqrt((du / fx)^2 + (dv / fy)^2)``, in increasing ``e``."""
    groups: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for k in range(2, _GRID_CAP + 1):
        for dv, du in _ring(k):
            groups.setdefault((abs(dv), abs(du)), []).append((dv, du))
    out = [(float(np.hypot(a[1] / fx, a[0] / fy)), tuple(v)) for a, v in groups.items()]
    return tuple(sorted(out))


def _beyond_cap(K: Intrinsics) -> float:
    """Smallest normalised length of an offset outside the grid's window cap."""
    return (_GRID_CAP + 1) / max(K.fx, K.fy)


class _Grid:
    """Flat padded image layout: pixel ``(v, u)`` sits at ``(v + pad) * Wp + u + pad``.

    Invalid pixels (and the border) hold far-away points, each at its own position
    (``_SENTINEL`` metres apart), so no distance test ever pairs them. Shifting an image by a pixel
    offset is then a contiguous slice; the dense work is split into row strips that stay in cache
    and run on threads (numpy releases the GIL).
    """

    def __init__(self, shape: tuple[int, int], pad: int = _GRID_CAP) -> None:
        self.H, self.W = shape
        self.pad, self.Wp = pad, self.W + 2 * pad
        self.size = (self.H + 2 * pad) * self.Wp
        self.base = pad * self.Wp
        rows = max(4, _STRIP_ELEMENTS // self.Wp)
        self.strips = [(v0, min(v0 + rows, self.H)) for v0 in range(0, self.H, rows)]

    def offset(self, dv: int, du: int) -> int:
        return dv * self.Wp + du

    def start(self, v0: int) -> int:
        """Flat index of the first element (left border column) of row ``v0``."""
        return self.base + v0 * self.Wp

    def core(self, flat: np.ndarray) -> np.ndarray:
        return flat[self.base:self.base + self.H * self.Wp].reshape(self.H, self.Wp)[:, self.pad:self.pad + self.W]

    def embed_points(self, depth: np.ndarray, valid: np.ndarray, xn: np.ndarray, yn: np.ndarray) -> list[np.ndarray]:
        """Points ``z * (xn, yn, 1)`` as three flat padded arrays, invalid pixels at sentinel positions."""
        far = _far(self.size)
        z = depth.astype(np.float64)
        out = []
        for c in range(3):
            a = far.copy()
            core = self.core(a)
            np.copyto(core, z if c == 2 else (xn if c == 0 else yn) * z, where=valid)
            out.append(a)
        return out

    def flat_index(self, v: np.ndarray, u: np.ndarray) -> np.ndarray:
        return (v + self.pad) * self.Wp + u + self.pad


@lru_cache(maxsize=4)
def _far(size: int) -> np.ndarray:
    a = _SENTINEL * (1.0 + np.arange(size, dtype=np.float64))
    a.setflags(write=False)
    return a


def _crop_box(vv: np.ndarray, uu: np.ndarray, shape: tuple[int, int]) -> tuple[slice, slice]:
    """Bounding box of the pixels ``(vv, uu)`` grown by the window cap: every pixel a window search
    from them can visit lies inside."""
    return (slice(max(int(vv.min()) - _GRID_CAP, 0), min(int(vv.max()) + _GRID_CAP + 1, shape[0])),
            slice(max(int(uu.min()) - _GRID_CAP, 0), min(int(uu.max()) + _GRID_CAP + 1, shape[1])))


_POOLS: dict[int, ThreadPoolExecutor] = {}
_POOL_LOCK = threading.Lock()


def _run(fn, items, threads: int) -> list:
    """``[fn(*it) for it in items]``, on up to ``threads`` threads of a pool kept for the process
    (starting threads per call costs more than small strips take)."""
    if threads <= 1 or len(items) <= 1:
        return [fn(*it) for it in items]
    with _POOL_LOCK:
        pool = _POOLS.get(threads)
        if pool is None:
            pool = _POOLS[threads] = ThreadPoolExecutor(threads, thread_name_prefix=f"bench-metrics-{threads}")
    return list(pool.map(lambda it: fn(*it), items))


def _chunks(n: int, parts: int) -> list[tuple[int, int]]:
    edges = np.linspace(0, n, max(1, min(parts, n)) + 1).astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]


_PRODUCTS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def _strip_sums(G: _Grid, X: list[np.ndarray], r2: float, v0: int, v1: int) -> np.ndarray:
    """Ring-1 neighbourhood sums of the strip's pixels (rows ``v0..v1``) plus one halo row below.

    Every pair of 8-neighbours is visited once (offsets right/below) and added to both ends.
    Returns ``(10, (v1-v0+1)*Wp+2)``: count (self included), sums of ``q - p`` (3) and of their
    products (6), in the layout starting at row ``v0``.
    """
    L = (v1 - v0) * G.Wp
    s0 = G.start(v0)
    acc = np.zeros((10, L + G.Wp + 2))
    d, t = np.empty((3, L)), np.empty((3, L))
    d2, tmp = np.empty(L), np.empty(L)
    m = np.empty(L, bool)
    p = [X[c][s0:s0 + L] for c in range(3)]
    acc[0, :L] = 1.0                          # the point itself
    for dv, du in _half_ring(1):
        off = G.offset(dv, du)
        for c in range(3):
            np.subtract(X[c][s0 + off:s0 + off + L], p[c], out=d[c])
        np.multiply(d[0], d[0], out=d2)
        np.multiply(d[1], d[1], out=tmp)
        d2 += tmp
        np.multiply(d[2], d[2], out=tmp)
        d2 += tmp
        np.less_equal(d2, r2, out=m)
        acc[0, :L] += m
        acc[0, off:off + L] += m
        np.multiply(d, m, out=t)
        acc[1:4, :L] += t
        acc[1:4, off:off + L] -= t
        for k, (a, b) in enumerate(_PRODUCTS):
            np.multiply(t[a], d[b], out=tmp)
            acc[4 + k, :L] += tmp
            acc[4 + k, off:off + L] += tmp
    return acc


def _deep_sums(G: _Grid, X: list[np.ndarray], sums: np.ndarray, fp: np.ndarray, pos: np.ndarray,
               reach: np.ndarray, groups, r2: float) -> None:
    """Add the neighbours at Chebyshev distance >= 2 of the pixels ``fp`` (flat padded; ``pos`` their
    columns in ``sums``) to ``sums``.

    Offsets are visited in increasing normalised length ``e``, each only from the pixels whose
    ``reach`` (the normalised radius any neighbour can lie in) is at least ``e``.
    """
    p = None
    for e, offsets in groups:
        keep = reach >= e
        if p is None or not keep.all():
            fp, pos, reach = fp[keep], pos[keep], reach[keep]
            if fp.size == 0:
                return
            p = [X[c][fp] for c in range(3)]
        for dv, du in offsets:
            fq = fp + G.offset(dv, du)
            dx, dy, dz = X[0][fq] - p[0], X[1][fq] - p[1], X[2][fq] - p[2]
            hit = np.flatnonzero(dx * dx + dy * dy + dz * dz <= r2)
            if hit.size:
                ph = pos[hit]
                dh = (dx[hit], dy[hit], dz[hit])
                sums[0, ph] += 1.0
                for c in range(3):
                    sums[1 + c, ph] += dh[c]
                for j, (a, b) in enumerate(_PRODUCTS):
                    sums[4 + j, ph] += dh[a] * dh[b]


def _strip_closest(G: _Grid, Xr: list[np.ndarray], Xq: list[np.ndarray], fp: np.ndarray, v0: int,
                   v1: int) -> tuple[np.ndarray, np.ndarray]:
    """Closest denoised point among the 3x3 window of each scored pixel ``fp`` (flat padded, rows ``v0..v1``).

    Returns ``(squared distance, flat index of that point)``.
    """
    L = (v1 - v0) * G.Wp
    s0 = G.start(v0)
    offsets = sorted(G.offset(dv, du) for dv, du in _ring(0) + _ring(1))   # argmin: ties -> lowest pixel index
    D2 = np.empty((len(offsets), L))
    d, t = np.empty(L), np.empty(L)
    p = [Xr[c][s0:s0 + L] for c in range(3)]
    for k, off in enumerate(offsets):
        d2 = D2[k]
        np.subtract(Xq[0][s0 + off:s0 + off + L], p[0], out=d)
        np.multiply(d, d, out=d2)
        for c in (1, 2):
            np.subtract(Xq[c][s0 + off:s0 + off + L], p[c], out=d)
            np.multiply(d, d, out=t)
            d2 += t
    loc = fp - s0
    sub = D2[:, loc]
    arg = np.argmin(sub, axis=0)
    return sub[arg, np.arange(loc.size)], fp + np.asarray(offsets)[arg]


def _deep_closest(G: _Grid, Xr, Xq, fp, bd, qi, z, s, groups, beyond: float) -> np.ndarray:
    """Widen the closest-point search of pixels ``fp`` (in place on ``bd``/``qi``) until proven.

    After visiting every offset shorter than ``e`` (normalised), no unvisited pixel's point can be
    closer than ``e z / (s + e)``. Returns the positions still open after the window cap.
    """
    lengths = [e for e, _ in groups] + [beyond]
    todo = np.arange(fp.size)
    for g, (e, offsets) in enumerate(groups):
        bound = lengths[g] * z[todo] / (s[todo] + lengths[g]) * (1.0 - 1e-9)
        todo = todo[bd[todo] > bound * bound]
        if todo.size == 0:
            return todo
        ft = fp[todo]
        pk = [Xr[c][ft] for c in range(3)]
        bdt, qit = bd[todo], qi[todo]
        for dv, du in offsets:
            fq = ft + G.offset(dv, du)
            dx, dy, dz = Xq[0][fq] - pk[0], Xq[1][fq] - pk[1], Xq[2][fq] - pk[2]
            d2 = dx * dx + dy * dy + dz * dz
            closer = (d2 < bdt) | ((d2 == bdt) & (fq < qit))      # ties -> lowest pixel index
            if closer.any():
                bdt = np.where(closer, d2, bdt)
                qit = np.where(closer, fq, qit)
        bd[todo], qi[todo] = bdt, qit
    bound = beyond * z[todo] / (s[todo] + beyond) * (1.0 - 1e-9)
    return todo[bd[todo] > bound * bound]


def _closest_kdtree(cloud: np.ndarray, queries: np.ndarray, threads: int) -> np.ndarray:
    """Closest point of ``cloud`` (rows in pixel order) to each query; exact ties go to the lowest row.

    The 8 nearest candidates from the KD-tree are re-scored with the grid search's arithmetic, so
    both searches pick the same point when distances tie (common with depth quantised to 1 mm).
    """
    k = min(8, len(cloud))
    tree = cKDTree(cloud, balanced_tree=False, compact_nodes=False)     # built for a few queries: build fast
    _, cand = tree.query(queries, k=k, workers=threads)
    cand = cand.reshape(len(queries), k)
    c = cloud[np.minimum(cand, len(cloud) - 1)]
    d = c - queries[:, None, :]
    d2 = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2]
    d2[cand >= len(cloud)] = np.inf
    best = d2.min(axis=1, keepdims=True)
    pick = np.where(d2 == best, cand, np.iinfo(np.int64).max).min(axis=1)
    return cloud[pick]


def _ball_pairs(tree: cKDTree, queries: np.ndarray, r: float, self_index: np.ndarray):
    """Directed pairs (query position, tree index) within ``r``, excluding each query's own point."""
    lists = tree.query_ball_point(queries, r, return_sorted=False)
    lengths = np.fromiter((len(x) for x in lists), dtype=np.int64, count=len(lists))
    j = np.fromiter((k for x in lists for k in x), dtype=np.int64, count=int(lengths.sum()))
    i = np.repeat(np.arange(len(lists)), lengths)
    keep = j != self_index[i]
    return i[keep], j[keep]


def _neighbour_sums_pairs(pts, pos, i, j):
    """Neighbourhood sums for the query points ``pos`` from pairs (query position ``i``, point ``j``).

    Returns ``(10, m)``: count (the point itself included), sums of ``q - p`` (3) and of the
    products ``(q - p)_a (q - p)_b`` (xx, xy, xz, yy, yz, zz).
    """
    d = pts[j] - pts[pos[i]]
    m = len(pos)
    out = np.empty((10, m))
    out[0] = np.bincount(i, minlength=m) + 1.0
    for c in range(3):
        out[1 + c] = np.bincount(i, weights=d[:, c], minlength=m)
    for k, (a, b) in enumerate(_PRODUCTS):
        out[4 + k] = np.bincount(i, weights=d[:, a] * d[:, b], minlength=m)
    return out


def _planes_from_sums(sums: np.ndarray, min_neighbors: int, min_spread_ratio: float):
    """``(10, m)`` neighbourhood sums to (centroid offset ``(m, 3)``, normal ``(m, 3)``, status ``(m,)``)."""
    n = sums[0]
    with np.errstate(invalid="ignore", divide="ignore"):
        inv_n = 1.0 / n
    mu_all = sums[1:4] * inv_n
    mean = mu_all.T
    status = np.full(n.size, 2, np.int8)
    normal = np.full((n.size, 3), np.nan)
    ok = n >= min_neighbors
    fit = slice(None) if ok.all() else np.flatnonzero(ok)
    if ok.any():
        mu, Sf, inv = mu_all[:, fit], sums[4:10, fit], inv_n[fit]
        C = [Sf[k] * inv - mu[a] * mu[c] for k, (a, c) in enumerate(_PRODUCTS)]
        _, lam_mid, lam_max, v = smallest_eigh3(*C)
        with np.errstate(invalid="ignore"):
            plane = (lam_mid > (min_spread_ratio ** 2) * lam_max) & np.isfinite(v).all(axis=1)
        status[fit] = np.where(plane, 1, 3)
        normal[fit] = v
    return mean, normal, status


@dataclass
class ReferencePlanes:
    """The least-squares plane of every reference point's radius neighbourhood.

    Attributes:
        mask: ``(H, W)`` bool, the reference points ``R``.
        index: ``(N,)`` flat pixel indices of ``R`` (row-major, increasing).
        position: ``(H*W,)`` int32, the position of each pixel in ``index`` (-1 outside ``R``).
        points: ``(N, 3)`` reference points, metres.
        neighbors: ``(N,)`` neighbourhood sizes (the point itself included).
        centroid_offset: ``(N, 3)`` neighbourhood centroid minus point, metres.
        normal: ``(N, 3)`` unit plane normals (NaN where excluded).
        status: ``(N,)`` int8: 1 plane, 2 too few neighbours, 3 degenerate.
        method: ``"grid"`` or ``"kdtree"``.
    """

    mask: np.ndarray
    index: np.ndarray
    position: np.ndarray
    points: np.ndarray
    neighbors: np.ndarray
    centroid_offset: np.ndarray
    normal: np.ndarray
    status: np.ndarray
    method: str
    radius_m: float
    intrinsics: Intrinsics
    grid_points: list[np.ndarray] | None = None   # the points in _Grid layout (grid method)
    grid_index: np.ndarray | None = None          # (N,) flat padded index of each point (grid method)
    crop: tuple[slice, slice] | None = None       # the image window the grid covers (grid method)
    pixel_normals: tuple | None = None            # the reference's normal components, filled by frame_metrics


def _resolve_method(method: str, intrinsics: Intrinsics) -> str:
    if method not in PLANE_FIT_METHODS:
        raise MetricInputError(f"plane-fit method must be one of {', '.join(PLANE_FIT_METHODS)}, got {method!r}")
    if method == "auto":
        return "kdtree" if intrinsics.has_distortion else "grid"
    if method == "grid" and intrinsics.has_distortion:
        raise MetricInputError("the grid plane-fit search needs distortion-free intrinsics; use method='kdtree'")
    return method


def fit_reference_planes(ref: np.ndarray, intrinsics: Intrinsics, *, roi: np.ndarray | None = None,
                         radius_m: float = 0.005, min_neighbors: int = 3, min_spread_ratio: float = 0.1,
                         method: str = "auto", threads: int = 1) -> ReferencePlanes:
    """Fit the plane of every reference point (first half of :func:`plane_fit_rmse`, reusable across methods).

    Args:
        ref: ``(H, W)`` reference depth, metres, NaN = none.
        intrinsics: the LQ camera (its size must be ``(H, W)``).
        roi: optional ``(H, W)`` bool region of interest.
        radius_m, min_neighbors, min_spread_ratio: see :class:`MetricConfig`.
        method: ``"grid"``, ``"kdtree"`` or ``"auto"`` (grid unless the intrinsics have distortion).
        threads: threads for the grid search and the KD-tree queries.
    """
    MetricConfig(radius_m=radius_m, min_neighbors=min_neighbors, min_spread_ratio=min_spread_ratio)
    if ref.ndim != 2 or intrinsics.shape != ref.shape:
        raise MetricInputError(f"intrinsics are {intrinsics.width}x{intrinsics.height}, depth has shape {ref.shape}")
    if roi is not None and roi.shape != ref.shape:
        raise MetricInputError(f"ROI mask {roi.shape} must have the reference's shape {ref.shape}")
    method = _resolve_method(method, intrinsics)
    r = float(radius_m)
    H, W = ref.shape
    xn, yn, sq = _rays(intrinsics)
    R = reference_mask(ref, roi)
    vv, uu = np.nonzero(R)
    idx = vv * W + uu
    position = np.full(H * W, -1, np.int32)
    position[idx] = np.arange(idx.size, dtype=np.int32)
    z = ref.ravel()[idx].astype(np.float64)
    pts = np.empty((idx.size, 3))
    np.multiply(xn.ravel()[idx], z, out=pts[:, 0])
    np.multiply(yn.ravel()[idx], z, out=pts[:, 1])
    pts[:, 2] = z
    N = idx.size
    if N == 0:
        return ReferencePlanes(R, idx, position, pts, np.zeros(0, np.int32), np.zeros((0, 3)), np.zeros((0, 3)),
                               np.zeros(0, np.int8), method, r, intrinsics)
    grid_points = grid_index = None
    if method == "grid":
        crop = _crop_box(vv, uu, ref.shape)     # the reference's bounding box plus the window cap
        G = _Grid((crop[0].stop - crop[0].start, crop[1].stop - crop[1].start))
        X = grid_points = G.embed_points(ref[crop], R[crop], xn[crop], yn[crop])
        fi = grid_index = G.flat_index(vv - crop[0].start, uu - crop[1].start)
        with np.errstate(divide="ignore", invalid="ignore"):
            reach = np.where(z > r, r * sq.ravel()[idx] / (z - r), np.inf) * (1.0 + 1e-9) + 1e-12
        beyond = _beyond_cap(intrinsics)
        fallback = reach >= beyond
        parts = _run(lambda v0, v1: _strip_sums(G, X, r * r, v0, v1), G.strips, threads)
        for k in range(len(parts) - 1):          # each strip's halo row belongs to the next strip
            parts[k + 1][:, :G.Wp + 2] += parts[k][:, -(G.Wp + 2):]
        sums = np.empty((10, N))
        cuts = np.searchsorted(idx, [(crop[0].start + v0) * W for v0, _ in G.strips] + [H * W])

        def gather(k):
            a, b = cuts[k], cuts[k + 1]
            v0, v1 = G.strips[k]
            if b - a == (v1 - v0) * G.W:        # every pixel of the strip is a reference point: a plain copy
                core = parts[k][:, :(v1 - v0) * G.Wp].reshape(10, v1 - v0, G.Wp)[:, :, G.pad:G.pad + G.W]
                sums[:, a:b] = core.reshape(10, -1)
            else:
                sums[:, a:b] = parts[k][:, fi[a:b] - G.start(v0)]

        _run(gather, [(k,) for k in range(len(parts))], threads)
        del parts
        groups = _deep_groups(intrinsics.fx, intrinsics.fy)
        deep = np.flatnonzero((reach >= groups[0][0]) & ~fallback)
        if deep.size:
            _run(lambda a, b: _deep_sums(G, X, sums, fi[deep[a:b]], deep[a:b], reach[deep[a:b]], groups, r * r),
                 _chunks(deep.size, max(threads, deep.size // _STRIP_ELEMENTS)), threads)
        mean = np.empty((N, 3))
        normal = np.empty((N, 3))
        status = np.empty(N, np.int8)

        def planes_of(a, b):
            mean[a:b], normal[a:b], status[a:b] = _planes_from_sums(sums[:, a:b], min_neighbors, min_spread_ratio)

        _run(planes_of, _chunks(N, max(threads, N // _STRIP_ELEMENTS)), threads)
        count = sums[0].copy()
        fb_pos = np.flatnonzero(fallback)
        if fb_pos.size:   # points so close to the camera that the window cap is too small
            i, j = _ball_pairs(cKDTree(pts), pts[fb_pos], r, fb_pos)
            fb_sums = _neighbour_sums_pairs(pts, fb_pos, i, j)
            mean[fb_pos], normal[fb_pos], status[fb_pos] = _planes_from_sums(fb_sums, min_neighbors, min_spread_ratio)
            count[fb_pos] = fb_sums[0]
    else:
        pairs = cKDTree(pts).query_pairs(r, output_type="ndarray")
        i = np.concatenate([pairs[:, 0], pairs[:, 1]])
        j = np.concatenate([pairs[:, 1], pairs[:, 0]])
        sums = _neighbour_sums_pairs(pts, np.arange(N), i, j)
        mean, normal, status = _planes_from_sums(sums, min_neighbors, min_spread_ratio)
        count = sums[0]
    return ReferencePlanes(R, idx, position, pts, count.astype(np.int32), mean, normal, status, method, r,
                           intrinsics, grid_points, grid_index, crop if method == "grid" else None)


def plane_fit_rmse(pred: np.ndarray, ref: np.ndarray, intrinsics: Intrinsics, *, roi: np.ndarray | None = None,
                   radius_m: float = 0.005, min_neighbors: int = 3, min_spread_ratio: float = 0.1,
                   method: str = "auto", planes: ReferencePlanes | None = None, threads: int = 1) -> PlaneFitResult:
    """DDD's plane-fit RMSE of ``pred`` against ``ref`` (see the module docstring).

    Args:
        pred, ref: ``(H, W)`` depth in metres, NaN = none.
        intrinsics: the LQ camera both depths live in (its size must be ``(H, W)``).
        roi: optional ``(H, W)`` bool region of interest (applies to both clouds).
        radius_m: neighbourhood radius in metres.
        min_neighbors: fewest points (self included) for a plane.
        min_spread_ratio: line-like neighbourhoods (second spread below this share of the first) are excluded.
        method: ``"grid"`` (organised search, needs distortion-free intrinsics), ``"kdtree"`` or
            ``"auto"`` (grid when possible). Both are exact and give the same result.
        planes: :func:`fit_reference_planes` of this ``ref``/``roi`` to reuse (the radius,
            thresholds and method above are then ignored).
        threads: threads for the grid search and the KD-tree queries.

    Returns:
        A :class:`PlaneFitResult` (``rmse_mm`` and per-pixel distances, neighbour counts, status).
    """
    _check_pair(pred, ref, roi)
    if planes is None:
        planes = fit_reference_planes(ref, intrinsics, roi=roi, radius_m=radius_m, min_neighbors=min_neighbors,
                                      min_spread_ratio=min_spread_ratio, method=method, threads=threads)
    elif planes.intrinsics != intrinsics or planes.mask.shape != ref.shape:
        raise MetricInputError("the reference planes were fitted for another camera or image size")
    H, W = ref.shape
    pred_valid = _finite_positive(pred)
    if roi is not None:
        pred_valid &= roi.astype(bool)
    eval_mask = planes.mask & pred_valid
    status = np.zeros((H, W), np.int8)
    distance = np.full((H, W), np.nan)
    neighbors = np.zeros((H, W), np.int32)
    ev = np.flatnonzero(eval_mask)
    if ev.size == 0:
        return PlaneFitResult(float("nan"), distance, neighbors, status, planes.method)
    pos = planes.position[ev]
    st = planes.status[pos]
    used = np.flatnonzero(st == 1)          # only planes need a closest point
    ev_used, pos_used = ev[used], pos[used]
    p_used = planes.points[pos_used]
    xn, yn, sq = _rays(intrinsics)
    q = np.empty((used.size, 3))
    todo = np.arange(used.size)
    if planes.method == "grid" and used.size:
        crop = planes.crop
        G = _Grid((crop[0].stop - crop[0].start, crop[1].stop - crop[1].start))
        Xq = G.embed_points(pred[crop], pred_valid[crop], xn[crop], yn[crop])
        fp = planes.grid_index[pos_used]
        cuts = np.searchsorted(ev_used, [(crop[0].start + v0) * W for v0, _ in G.strips] + [H * W])
        bd, qi = np.empty(used.size), np.empty(used.size, np.int64)

        def near(v0, v1, a, b):
            bd[a:b], qi[a:b] = _strip_closest(G, planes.grid_points, Xq, fp[a:b], v0, v1)

        _run(near, [(v0, v1, a, b) for (v0, v1), a, b in zip(G.strips, cuts[:-1], cuts[1:]) if b > a], threads)
        z = p_used[:, 2]
        s = sq.ravel()[ev_used]
        groups = _deep_groups(intrinsics.fx, intrinsics.fy)
        bound = groups[0][0] * z / (s + groups[0][0]) * (1.0 - 1e-9)
        deep = np.flatnonzero(bd > bound * bound)
        open_parts = []
        if deep.size:
            def widen(a, b):
                sel = deep[a:b]
                sbd, sqi = bd[sel], qi[sel]
                still = _deep_closest(G, planes.grid_points, Xq, fp[sel], sbd, sqi, z[sel], s[sel], groups,
                                      _beyond_cap(intrinsics))
                bd[sel], qi[sel] = sbd, sqi
                open_parts.append(sel[still])

            _run(widen, _chunks(deep.size, max(threads, deep.size // _STRIP_ELEMENTS)), threads)
        for c in range(3):
            q[:, c] = Xq[c][qi]
        todo = np.sort(np.concatenate(open_parts)) if open_parts else todo[:0]
    if todo.size:
        qv = np.flatnonzero(pred_valid)
        zq = pred.ravel()[qv].astype(np.float64)
        q[todo] = _closest_kdtree(np.stack([xn.ravel()[qv] * zq, yn.ravel()[qv] * zq, zq], axis=1), p_used[todo],
                                  threads)
    dist = np.abs(np.einsum("ij,ij->i", planes.normal[pos_used], q - p_used - planes.centroid_offset[pos_used]))
    status.ravel()[ev] = st
    neighbors.ravel()[ev] = planes.neighbors[pos]
    distance.ravel()[ev_used] = dist
    rmse = float(np.sqrt(np.mean(dist ** 2)) * 1000.0) if dist.size else float("nan")
    return PlaneFitResult(rmse, distance, neighbors, status, planes.method)


# --------------------------------------------------------------------------------- one frame
def frame_metrics(pred: np.ndarray, ref: np.ndarray, intrinsics: Intrinsics, *, roi: np.ndarray | None = None,
                  config: MetricConfig = MetricConfig(), planes: ReferencePlanes | None = None,
                  plane_fit_method: str = "auto", threads: int = 1) -> tuple[dict[str, float], list[dict[str, float]]]:
    """Every metric of one frame against one reference.

    Args:
        pred, ref: ``(H, W)`` depth in metres, NaN = none.
        intrinsics: the LQ camera.
        roi: optional ``(H, W)`` bool region of interest.
        config: metric parameters.
        planes: :func:`fit_reference_planes` of ``ref``/``roi`` with ``config`` (reused across methods).
        plane_fit_method: ``"auto"``, ``"grid"`` or ``"kdtree"`` (equal results).
        threads: threads for the plane fit (results do not depend on it).

    Returns:
        ``(metrics, bins)``: ``metrics`` maps every name of :data:`UNITS` to a float; ``bins`` lists
        ``{"bin_lo_m", "bin_hi_m", <every name of BINNED>}`` for the reference-depth bins of width
        ``config.depth_bin_m`` that hold at least one reference pixel.
    """
    _check_pair(pred, ref, roi)
    if planes is None:
        planes = fit_reference_planes(ref, intrinsics, roi=roi, radius_m=config.radius_m,
                                      min_neighbors=config.min_neighbors, min_spread_ratio=config.min_spread_ratio,
                                      method=plane_fit_method, threads=threads)
    R = planes.mask
    M = R & _finite_positive(pred)
    out = {"n_reference": float(np.count_nonzero(R))}
    pe = pixel_errors(pred, ref, roi)
    out["n_valid"] = float(pe.pop("n_valid"))
    out["fill_rate"] = out["n_valid"] / out["n_reference"] if out["n_reference"] else float("nan")
    out.update(pe)
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
