"""DDD's plane-fit RMSE (Sterzentsenko et al.; seed report section IV): pure numpy/scipy, no I/O.

Depths are ``(H, W)`` float arrays in metres with NaN for "no measurement"; ``R`` and ``M`` are the
reference and scored pixel sets of :mod:`bench.masks`; distances are reported in millimetres.

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

The searches themselves are in :mod:`bench.plane_search`; this module fits the planes and scores.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from bench.errors import MetricInputError
from bench.masks import check_pair, finite_positive, reference_mask
from bench.plane_search import (PRODUCTS, STRIP_ELEMENTS, Grid, ball_pairs, beyond_cap, chunks, closest_kdtree,
                                crop_box, deep_closest, deep_groups, deep_sums, neighbour_sums_pairs, rays,
                                run_threads, strip_closest, strip_sums)
from capture.camera import Intrinsics

PLANE_FIT_METHODS = ("auto", "grid", "kdtree")


def check_plane_parameters(*, radius_m: float, min_neighbors: int, min_spread_ratio: float) -> None:
    """Raise :class:`MetricInputError` naming the value unless the plane-fit parameters can be used."""
    if not (np.isfinite(radius_m) and radius_m > 0):
        raise MetricInputError(f"plane-fit radius must be positive, got {radius_m} m")
    if int(min_neighbors) != min_neighbors or min_neighbors < 3:
        raise MetricInputError(f"min_neighbors must be an integer >= 3 (a plane needs 3 points), got {min_neighbors}")
    if not 0 <= min_spread_ratio < 1:
        raise MetricInputError(f"min_spread_ratio must lie in [0, 1), got {min_spread_ratio}")


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


# --------------------------------------------------------------------------------- planes
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
        radius_m: the neighbourhood radius, metres; intrinsics: the camera the points were unprojected with.
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
    grid_points: list[np.ndarray] | None = None   # the points in plane_search.Grid layout (grid method)
    grid_index: np.ndarray | None = None          # (N,) flat padded index of each point (grid method)
    crop: tuple[slice, slice] | None = None       # the image window the grid covers (grid method)
    pixel_normals: tuple | None = None            # the reference's normal components, filled by frame_metrics


def planes_from_sums(sums: np.ndarray, min_neighbors: int, min_spread_ratio: float):
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
        C = [Sf[k] * inv - mu[a] * mu[c] for k, (a, c) in enumerate(PRODUCTS)]
        _, lam_mid, lam_max, v = smallest_eigh3(*C)
        with np.errstate(invalid="ignore"):
            plane = (lam_mid > (min_spread_ratio ** 2) * lam_max) & np.isfinite(v).all(axis=1)
        status[fit] = np.where(plane, 1, 3)
        normal[fit] = v
    return mean, normal, status


def _resolve_method(method: str, intrinsics: Intrinsics) -> str:
    if method not in PLANE_FIT_METHODS:
        raise MetricInputError(f"plane-fit method must be one of {', '.join(PLANE_FIT_METHODS)}, got {method!r}")
    if method == "auto":
        return "kdtree" if intrinsics.has_distortion else "grid"
    if method == "grid" and intrinsics.has_distortion:
        raise MetricInputError("the grid plane-fit search needs distortion-free intrinsics; use method='kdtree'")
    return method


def _reference_points(ref: np.ndarray, R: np.ndarray, intrinsics: Intrinsics):
    """Flat indices ``(N,)`` of the pixels ``R``, their positions ``(H*W,)`` and points ``(N, 3)`` in metres."""
    H, W = ref.shape
    xn, yn, _ = rays(intrinsics)
    vv, uu = np.nonzero(R)
    idx = vv * W + uu
    position = np.full(H * W, -1, np.int32)
    position[idx] = np.arange(idx.size, dtype=np.int32)
    z = ref.ravel()[idx].astype(np.float64)
    pts = np.empty((idx.size, 3))
    np.multiply(xn.ravel()[idx], z, out=pts[:, 0])
    np.multiply(yn.ravel()[idx], z, out=pts[:, 1])
    pts[:, 2] = z
    return idx, position, pts


def fit_reference_planes(ref: np.ndarray, intrinsics: Intrinsics, *, roi: np.ndarray | None = None,
                         radius_m: float = 0.005, min_neighbors: int = 3, min_spread_ratio: float = 0.1,
                         method: str = "auto", threads: int = 1) -> ReferencePlanes:
    """Fit the plane of every reference point (first half of :func:`plane_fit_rmse`, reusable across methods).

    Args:
        ref: ``(H, W)`` reference depth, metres, NaN = none.
        intrinsics: the LQ camera (its size must be ``(H, W)``).
        roi: optional ``(H, W)`` bool region of interest.
        radius_m, min_neighbors, min_spread_ratio: see :class:`bench.metrics.MetricConfig`.
        method: ``"grid"``, ``"kdtree"`` or ``"auto"`` (grid unless the intrinsics have distortion).
        threads: threads for the grid search and the KD-tree queries.
    """
    check_plane_parameters(radius_m=radius_m, min_neighbors=min_neighbors, min_spread_ratio=min_spread_ratio)
    if ref.ndim != 2 or intrinsics.shape != ref.shape:
        raise MetricInputError(f"intrinsics are {intrinsics.width}x{intrinsics.height}, depth has shape {ref.shape}")
    if roi is not None and roi.shape != ref.shape:
        raise MetricInputError(f"ROI mask {roi.shape} must have the reference's shape {ref.shape}")
    method = _resolve_method(method, intrinsics)
    R = reference_mask(ref, roi)
    idx, position, pts = _reference_points(ref, R, intrinsics)
    planes = ReferencePlanes(mask=R, index=idx, position=position, points=pts, neighbors=np.zeros(0, np.int32),
                             centroid_offset=np.zeros((0, 3)), normal=np.zeros((0, 3)), status=np.zeros(0, np.int8),
                             method=method, radius_m=float(radius_m), intrinsics=intrinsics)
    if idx.size and method == "grid":
        _fit_grid(planes, ref, min_neighbors=min_neighbors, min_spread_ratio=min_spread_ratio, threads=threads)
    elif idx.size:
        pairs = cKDTree(pts).query_pairs(planes.radius_m, output_type="ndarray")
        i = np.concatenate([pairs[:, 0], pairs[:, 1]])
        j = np.concatenate([pairs[:, 1], pairs[:, 0]])
        sums = neighbour_sums_pairs(pts, np.arange(idx.size), i, j)
        planes.centroid_offset, planes.normal, planes.status = planes_from_sums(sums, min_neighbors, min_spread_ratio)
        planes.neighbors = sums[0].astype(np.int32)
    return planes


def _ring1_sums(G: Grid, X: list[np.ndarray], fi: np.ndarray, *, cuts: np.ndarray, r2: float,
                threads: int) -> np.ndarray:
    """``(10, N)`` ring-1 neighbourhood sums of the points at flat padded indices ``fi`` (increasing;
    ``cuts[k]:cuts[k+1]`` are those in row strip ``k``), computed strip by strip."""
    parts = run_threads(lambda v0, v1: strip_sums(G, X, r2, v0, v1), G.strips, threads)
    for k in range(len(parts) - 1):          # each strip's halo row belongs to the next strip
        parts[k + 1][:, :G.Wp + 2] += parts[k][:, -(G.Wp + 2):]
    sums = np.empty((10, fi.size))

    def gather(k):
        a, b = cuts[k], cuts[k + 1]
        v0, v1 = G.strips[k]
        if b - a == (v1 - v0) * G.W:        # every pixel of the strip is a reference point: a plain copy
            core = parts[k][:, :(v1 - v0) * G.Wp].reshape(10, v1 - v0, G.Wp)[:, :, G.pad:G.pad + G.W]
            sums[:, a:b] = core.reshape(10, -1)
        else:
            sums[:, a:b] = parts[k][:, fi[a:b] - G.start(v0)]

    run_threads(gather, [(k,) for k in range(len(parts))], threads)
    return sums


def _fit_grid(planes: ReferencePlanes, ref: np.ndarray, *, min_neighbors: int, min_spread_ratio: float,
              threads: int) -> None:
    """The planes of ``planes.points`` by the organised (image) search, filled into ``planes``."""
    K, r, idx, pts = planes.intrinsics, planes.radius_m, planes.index, planes.points
    H, W = ref.shape
    N = idx.size
    xn, yn, sq = rays(K)
    vv, uu = np.divmod(idx, W)
    crop = crop_box(vv, uu, ref.shape)     # the reference's bounding box plus the window cap
    G = Grid((crop[0].stop - crop[0].start, crop[1].stop - crop[1].start))
    X = G.embed_points(ref[crop], planes.mask[crop], xn[crop], yn[crop])
    fi = G.flat_index(vv - crop[0].start, uu - crop[1].start)
    z = pts[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        reach = np.where(z > r, r * sq.ravel()[idx] / (z - r), np.inf) * (1.0 + 1e-9) + 1e-12
    fallback = reach >= beyond_cap(K)
    cuts = np.searchsorted(idx, [(crop[0].start + v0) * W for v0, _ in G.strips] + [H * W])
    sums = _ring1_sums(G, X, fi, cuts=cuts, r2=r * r, threads=threads)
    groups = deep_groups(K.fx, K.fy)
    deep = np.flatnonzero((reach >= groups[0][0]) & ~fallback)
    if deep.size:
        run_threads(lambda a, b: deep_sums(G, X, sums, fp=fi[deep[a:b]], pos=deep[a:b], reach=reach[deep[a:b]],
                                           groups=groups, r2=r * r),
                    chunks(deep.size, max(threads, deep.size // STRIP_ELEMENTS)), threads)
    mean, normal, status = np.empty((N, 3)), np.empty((N, 3)), np.empty(N, np.int8)

    def planes_of(a, b):
        mean[a:b], normal[a:b], status[a:b] = planes_from_sums(sums[:, a:b], min_neighbors, min_spread_ratio)

    run_threads(planes_of, chunks(N, max(threads, N // STRIP_ELEMENTS)), threads)
    count = sums[0].copy()
    fb_pos = np.flatnonzero(fallback)
    if fb_pos.size:   # points so close to the camera that the window cap is too small
        i, j = ball_pairs(cKDTree(pts), pts[fb_pos], r, fb_pos)
        fb_sums = neighbour_sums_pairs(pts, fb_pos, i, j)
        mean[fb_pos], normal[fb_pos], status[fb_pos] = planes_from_sums(fb_sums, min_neighbors, min_spread_ratio)
        count[fb_pos] = fb_sums[0]
    planes.neighbors, planes.centroid_offset, planes.normal, planes.status = count.astype(np.int32), mean, normal, status
    planes.grid_points, planes.grid_index, planes.crop = X, fi, crop


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
    check_pair(pred, ref, roi)
    if planes is None:
        planes = fit_reference_planes(ref, intrinsics, roi=roi, radius_m=radius_m, min_neighbors=min_neighbors,
                                      min_spread_ratio=min_spread_ratio, method=method, threads=threads)
    elif planes.intrinsics != intrinsics or planes.mask.shape != ref.shape:
        raise MetricInputError("the reference planes were fitted for another camera or image size")
    H, W = ref.shape
    pred_valid = finite_positive(pred)
    if roi is not None:
        pred_valid &= roi.astype(bool)
    status = np.zeros((H, W), np.int8)
    distance = np.full((H, W), np.nan)
    neighbors = np.zeros((H, W), np.int32)
    ev = np.flatnonzero(planes.mask & pred_valid)
    if ev.size == 0:
        return PlaneFitResult(rmse_mm=float("nan"), distance_m=distance, neighbors=neighbors, status=status,
                              method=planes.method)
    pos = planes.position[ev]
    st = planes.status[pos]
    used = np.flatnonzero(st == 1)          # only planes need a closest point
    ev_used, pos_used = ev[used], pos[used]
    p_used = planes.points[pos_used]
    q = _closest_points(pred, pred_valid, planes, ev_used, p_used, threads=threads)
    dist = np.abs(np.einsum("ij,ij->i", planes.normal[pos_used], q - p_used - planes.centroid_offset[pos_used]))
    status.ravel()[ev] = st
    neighbors.ravel()[ev] = planes.neighbors[pos]
    distance.ravel()[ev_used] = dist
    rmse = float(np.sqrt(np.mean(dist ** 2)) * 1000.0) if dist.size else float("nan")
    return PlaneFitResult(rmse_mm=rmse, distance_m=distance, neighbors=neighbors, status=status, method=planes.method)


def _closest_points(pred: np.ndarray, pred_valid: np.ndarray, planes: ReferencePlanes, ev: np.ndarray,
                    p: np.ndarray, *, threads: int) -> np.ndarray:
    """``(n, 3)`` closest denoised point to each reference point ``p`` ``(n, 3)`` (flat pixels ``ev``):
    the grid search where it can prove its answer, the KD-tree for the rest."""
    xn, yn, _ = rays(planes.intrinsics)
    q = np.empty((ev.size, 3))
    todo = np.arange(ev.size)
    if planes.method == "grid" and ev.size:
        todo = _closest_grid(pred, pred_valid, planes, ev, z=p[:, 2], q=q, threads=threads)
    if todo.size:
        qv = np.flatnonzero(pred_valid)
        zq = pred.ravel()[qv].astype(np.float64)
        q[todo] = closest_kdtree(np.stack([xn.ravel()[qv] * zq, yn.ravel()[qv] * zq, zq], axis=1), p[todo], threads)
    return q


def _closest_grid(pred: np.ndarray, pred_valid: np.ndarray, planes: ReferencePlanes, ev: np.ndarray, *,
                  z: np.ndarray, q: np.ndarray, threads: int) -> np.ndarray:
    """Grid closest-point search for the scored pixels ``ev`` (reference depth ``z``), written into ``q``.

    Returns the positions (sorted) whose answer the window cap could not prove (for the KD-tree).
    """
    K, crop = planes.intrinsics, planes.crop
    H, W = pred.shape
    xn, yn, sq = rays(K)
    G = Grid((crop[0].stop - crop[0].start, crop[1].stop - crop[1].start))
    Xq = G.embed_points(pred[crop], pred_valid[crop], xn[crop], yn[crop])
    fp = planes.grid_index[planes.position[ev]]
    cuts = np.searchsorted(ev, [(crop[0].start + v0) * W for v0, _ in G.strips] + [H * W])
    bd, qi = np.empty(ev.size), np.empty(ev.size, np.int64)

    def near(v0, v1, a, b):
        bd[a:b], qi[a:b] = strip_closest(G, planes.grid_points, Xq, fp[a:b], v0=v0, v1=v1)

    run_threads(near, [(v0, v1, a, b) for (v0, v1), a, b in zip(G.strips, cuts[:-1], cuts[1:]) if b > a], threads)
    s = sq.ravel()[ev]
    groups = deep_groups(K.fx, K.fy)
    bound = groups[0][0] * z / (s + groups[0][0]) * (1.0 - 1e-9)
    deep = np.flatnonzero(bd > bound * bound)
    open_parts = []
    if deep.size:
        def widen(a, b):
            sel = deep[a:b]
            sbd, sqi = bd[sel], qi[sel]
            still = deep_closest(G, planes.grid_points, Xq, fp[sel], bd=sbd, qi=sqi, z=z[sel], s=s[sel],
                                 groups=groups, beyond=beyond_cap(K))
            bd[sel], qi[sel] = sbd, sqi
            open_parts.append(sel[still])

        run_threads(widen, chunks(deep.size, max(threads, deep.size // STRIP_ELEMENTS)), threads)
    for c in range(3):
        q[:, c] = Xq[c][qi]
    return np.sort(np.concatenate(open_parts)) if open_parts else np.arange(0)
