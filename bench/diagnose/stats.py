"""Error statistics of a depth sensor against a reference (pure numpy/OpenCV, no I/O).

Every statistic takes a measured depth image ``depth`` and a reference ``reference`` (both
``(H, W)`` float32 metres, NaN = none) and works on the residual ``r = depth - reference``:

* :func:`robust_plane` / :func:`plane_depth`: a plane fitted with iteratively re-weighted
  trimming (3 x 1.4826 MAD), and the depth it implies along each pixel's ray, ``z = d / (n . ray)``;
* :func:`tile_plane_reference`: a reference for captures without one: square tiles whose points
  lie on a plane (a robust fit leaves a residual scale in the lowest ``keep_quantile`` of the
  tiles of similar depth) take that plane as their reference;
* :func:`binned`: per depth bin the robust random error (``1.4826 * MAD`` of the residual), the
  mean residual (bias), the count; :func:`fill_by`: the valid fraction per bin of any quantity;
* :func:`position_bias`: the mean residual on a coarse grid of the image;
* :func:`autocorrelation`: the correlation of the residual with itself shifted by 1..L pixels;
* :func:`edge_errors`: flying pixels (between the two sides of a depth jump) and edge
  fattening (background pixels measured at the foreground depth) next to reference edges: the
  discontinuities of :func:`jump_pixels`, where the depth changes by more than the surface's own slope
  predicts (a floor seen at a grazing angle changes by more than the jump from row to row without an edge);
* :func:`depth_steps`: the smallest step between distinct measured depths per depth bin (the
  quantisation of a stereo camera's disparity shows as steps growing as ``z**2``).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

MAD_TO_SIGMA = 1.4826


def robust_sigma(x: np.ndarray) -> float:
    """``1.4826 * median(|x - median(x)|)``: the standard deviation of Gaussian data, robust to outliers.

    >>> round(robust_sigma(np.random.default_rng(0).normal(0, 2.0, 100000)), 2)
    2.0
    """
    x = np.asarray(x, np.float64)
    if x.size == 0:
        return float("nan")
    return float(MAD_TO_SIGMA * np.median(np.abs(x - np.median(x))))


# ----------------------------------------------------------------------------- planes
@dataclass(frozen=True)
class Plane:
    """``n . p = d`` in the camera frame (``n`` unit, facing the camera: ``d > 0``), metres."""

    n: np.ndarray
    d: float
    rms_m: float
    inlier_fraction: float


def robust_plane(points: np.ndarray, *, iterations: int = 6, k: float = 3.0) -> Plane:
    """Fit a plane to ``points`` ``(N, 3)`` metres, trimming points beyond ``k`` robust sigmas.

    >>> rng = np.random.default_rng(0)
    >>> P = np.c_[rng.uniform(-1, 1, (500, 2)), np.full(500, 2.0)]
    >>> P[:20, 2] = 9.0  # outliers
    >>> p = robust_plane(P); round(p.d, 6), round(float(abs(p.n[2])), 6)
    (2.0, 1.0)
    """
    P = np.asarray(points, np.float64)
    keep = _lmeds_inliers(P, k)
    c, n = P.mean(axis=0), np.array([0.0, 0.0, 1.0])
    for _ in range(iterations):
        if keep.sum() < 3:
            break
        c = P[keep].mean(axis=0)
        n = np.linalg.svd(P[keep] - c, full_matrices=False)[2][2]
        r = (P - c) @ n
        scale = MAD_TO_SIGMA * np.median(np.abs(r[keep]))
        keep = np.abs(r) <= k * scale + 1e-6
    d = float(c @ n)
    if d < 0:
        n, d = -n, -d
    r = P[keep] @ n - d
    return Plane(n, d, float(np.sqrt(np.mean(r ** 2))) if r.size else float("nan"), float(keep.mean()))


def _lmeds_inliers(P: np.ndarray, k: float, trials: int = 48) -> np.ndarray:
    """Start of :func:`robust_plane`: the plane through 3 sample points with the least median
    residual (least median of squares, robust to up to half outliers), and the points within
    ``k`` robust sigmas of it. Deterministic (fixed seed)."""
    n_pts = len(P)
    if n_pts < 10:
        return np.ones(n_pts, bool)
    idx = np.random.default_rng(0).integers(0, n_pts, size=(trials, 3))
    a, b, c = P[idx[:, 0]], P[idx[:, 1]], P[idx[:, 2]]
    nrm = np.cross(b - a, c - a)
    length = np.linalg.norm(nrm, axis=1)
    ok = length > 1e-12
    if not ok.any():
        return np.ones(n_pts, bool)
    nrm, a = nrm[ok] / length[ok, None], a[ok]
    sub = P if n_pts <= 4000 else P[np.random.default_rng(1).integers(0, n_pts, 4000)]
    med = np.median(np.abs(sub @ nrm.T - np.sum(a * nrm, axis=1)), axis=0)
    best = int(np.argmin(med))
    r = np.abs(P @ nrm[best] - a[best] @ nrm[best])
    return r <= k * MAD_TO_SIGMA * max(med[best], 1e-9) + 1e-6


def plane_depth(plane: Plane, ray_xy: np.ndarray) -> np.ndarray:
    """Depth (z, metres) of ``plane`` along each ray ``(x, y, 1)``; ``ray_xy`` ``(H, W, 2)``."""
    denom = plane.n[0] * ray_xy[..., 0] + plane.n[1] * ray_xy[..., 1] + plane.n[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = plane.d / denom
    return np.where(z > 0, z, np.nan).astype(np.float32)


def tile_plane_reference(depth: np.ndarray, ray_xy: np.ndarray, *, tile: int = 24, min_valid: float = 0.6,
                         keep_quantile: float = 0.5, max_range_m: float = 0.5) -> np.ndarray:
    """A reference depth from local planes: NaN except on tiles that are planar.

    Args:
        depth: ``(H, W)`` measured depth, metres, NaN = none.
        ray_xy: ``(H, W, 2)`` undistorted normalised ray coordinates of the pixels.
        tile: tile side (px); min_valid: valid fraction a tile needs.
        keep_quantile: a tile is kept when its residual RMS over ``z**2`` (the stereo growth) is in
            this lowest quantile of all candidate tiles (curved or cluttered tiles are dropped).
        max_range_m: tiles whose 5-95 % depth range exceeds this (silhouettes) are skipped.
    Returns:
        ``(H, W)`` float32 reference depth (metres), the tile's plane, NaN outside kept tiles.
    """
    H, W = depth.shape
    cands = []
    for r0 in range(0, H - tile + 1, tile):
        for c0 in range(0, W - tile + 1, tile):
            z = depth[r0:r0 + tile, c0:c0 + tile]
            ok = np.isfinite(z)
            if ok.mean() < min_valid or np.subtract(*np.percentile(z[ok], [95, 5])) > max_range_m:
                continue
            xy = ray_xy[r0:r0 + tile, c0:c0 + tile][ok]
            P = np.c_[xy * z[ok][:, None], z[ok]]
            p = robust_plane(P)
            zm = float(np.median(z[ok]))
            cands.append((p.rms_m / zm ** 2, r0, c0, p))
    ref = np.full((H, W), np.nan, np.float32)
    if not cands:
        return ref
    limit = np.quantile([c[0] for c in cands], keep_quantile)
    for score, r0, c0, p in cands:
        if score <= limit:
            ref[r0:r0 + tile, c0:c0 + tile] = plane_depth(p, ray_xy[r0:r0 + tile, c0:c0 + tile])
    return ref


# ----------------------------------------------------------------------------- binned statistics
@dataclass(frozen=True)
class Binned:
    """Per bin of a quantity ``x``: centres, counts, robust sigma, mean, and its standard error."""

    centre: np.ndarray
    count: np.ndarray
    sigma: np.ndarray
    mean: np.ndarray
    sigma_se: np.ndarray

    def to_dict(self) -> dict:
        return {k: [None if not np.isfinite(v) else float(v) for v in getattr(self, k)]
                for k in ("centre", "count", "sigma", "mean", "sigma_se")}


def binned(x: np.ndarray, residual: np.ndarray, edges: np.ndarray, *, min_count: int = 50,
           clip_sigmas: float = 5.0, area_px: float = 1.0) -> Binned:
    """Random error and bias of ``residual`` (metres) in bins of ``x`` (``edges`` ascending).

    ``sigma``: the standard deviation within 4 robust (1.4826 MAD) sigmas of the median; ``mean``: the mean after dropping residuals beyond ``clip_sigmas``
    sigmas (far outliers); ``sigma_se``: ``sigma / sqrt(2 n_eff)`` with ``n_eff = n / area_px``
    (``area_px``: pixels per independent sample, >1 for correlated noise). Bins with fewer than
    ``min_count`` samples are NaN.
    """
    x, r = np.asarray(x, np.float64).ravel(), np.asarray(residual, np.float64).ravel()
    ok = np.isfinite(x) & np.isfinite(r)
    x, r = x[ok], r[ok]
    idx = np.digitize(x, edges) - 1
    nb = len(edges) - 1
    out = {k: np.full(nb, np.nan) for k in ("sigma", "mean", "sigma_se")}
    count = np.zeros(nb, np.int64)
    for b in range(nb):
        rb = r[idx == b]
        count[b] = rb.size
        if rb.size < min_count:
            continue
        # the robust centre and scale from at most ~100k evenly strided samples (ample precision)
        sub = rb[::max(1, rb.size // 100_000)]
        s0 = max(robust_sigma(sub), 1e-4)
        med = np.median(sub)
        # the MAD of depth stored in whole units is itself quantised (1.48, 2.97 mm...): the
        # reported sigma is the plain standard deviation inside +-4 robust sigmas instead
        s = float(rb[np.abs(rb - med) <= 4 * s0].std())
        inl = rb[np.abs(rb - med) <= clip_sigmas * s0]
        out["sigma"][b] = s
        out["mean"][b] = inl.mean()
        out["sigma_se"][b] = s / np.sqrt(2 * max(rb.size / max(area_px, 1.0), 2))
    return Binned(0.5 * (edges[:-1] + edges[1:]), count, out["sigma"], out["mean"], out["sigma_se"])


def fill_by(x: np.ndarray, valid: np.ndarray, edges: np.ndarray, *, min_count: int = 50) -> tuple[np.ndarray, np.ndarray]:
    """Valid fraction per bin of ``x``: ``(fraction (B,), count (B,))``; NaN below ``min_count``.

    >>> f, n = fill_by(np.array([0.5, 0.5, 1.5, 1.5]), np.array([1, 0, 1, 1], bool), np.array([0, 1, 2]), min_count=1)
    >>> f.tolist(), n.tolist()
    ([0.5, 1.0], [2, 2])
    """
    x, v = np.asarray(x, np.float64).ravel(), np.asarray(valid, bool).ravel()
    ok = np.isfinite(x)
    idx = np.digitize(x[ok], edges) - 1
    inside = (idx >= 0) & (idx < len(edges) - 1)
    n = np.bincount(idx[inside], minlength=len(edges) - 1)
    k = np.bincount(idx[inside], weights=v[ok][inside].astype(np.float64), minlength=len(edges) - 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(n >= min_count, k / np.maximum(n, 1), np.nan)
    return frac, n


def position_bias(residual: np.ndarray, *, cells: tuple[int, int] = (6, 8), min_count: int = 30) -> np.ndarray:
    """Mean residual (metres) on a ``cells`` = (rows, cols) grid of the image; NaN where too few."""
    H, W = residual.shape
    out = np.full(cells, np.nan)
    rs, cs = np.linspace(0, H, cells[0] + 1).astype(int), np.linspace(0, W, cells[1] + 1).astype(int)
    for i in range(cells[0]):
        for j in range(cells[1]):
            r = residual[rs[i]:rs[i + 1], cs[j]:cs[j + 1]]
            r = r[np.isfinite(r)]
            if r.size >= min_count:
                s = robust_sigma(r)
                out[i, j] = r[np.abs(r - np.median(r)) <= 5 * max(s, 1e-9)].mean()
    return out


# ----------------------------------------------------------------------------- spatial correlation
def autocorrelation(residual: np.ndarray, lags) -> tuple[np.ndarray, np.ndarray]:
    """Correlation coefficient of the residual with itself at ``lags`` (px, e.g. 1, 2, 4, 8).

    Averaged over horizontal and vertical shifts, NaN pixels skipped; residuals are divided by
    their robust sigma and clipped at 4 so that outliers do not dominate.
    Returns ``(rho (L,), pairs (L,))``.

    >>> white = np.random.default_rng(0).normal(size=(200, 200))
    >>> rho, n = autocorrelation(white, [1, 2]); bool(np.all(np.abs(rho) < 0.02))
    True
    """
    r = np.asarray(residual, np.float64)
    ok = np.isfinite(r)
    s = robust_sigma(r[ok]) if ok.any() else 1.0
    z = np.where(ok, np.clip((r - np.median(r[ok])) / max(s, 1e-12), -4, 4), 0.0) if ok.any() else np.zeros_like(r)
    lags = [int(v) for v in lags]
    rho, pairs = np.full(len(lags), np.nan), np.zeros(len(lags), np.int64)
    for j, lag in enumerate(lags):
        num = den_a = den_b = 0.0
        n = 0
        for a, b, ma, mb in ((z[:, :-lag], z[:, lag:], ok[:, :-lag], ok[:, lag:]),
                             (z[:-lag], z[lag:], ok[:-lag], ok[lag:])):
            m = ma & mb
            av, bv = a[m], b[m]
            # plain sums, not BLAS dot products: OpenBLAS threads spin on a busy machine
            num += float(np.sum(av * bv))
            den_a += float(np.sum(av * av))
            den_b += float(np.sum(bv * bv))
            n += int(m.sum())
        pairs[j] = n
        if n > 10 and den_a > 0 and den_b > 0:
            rho[j] = num / np.sqrt(den_a * den_b)
    return rho, pairs


# ----------------------------------------------------------------------------- depth edges
@dataclass(frozen=True)
class EdgeErrors:
    """Next to reference depth jumps: pixels examined, flying (between the sides), fattened
    (background pixel measured on the foreground), missing fraction; widths in pixels."""

    pixels: int
    flying_fraction: float
    fattened_fraction: float
    missing_fraction: float
    fattening_px: float

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in ("pixels", "flying_fraction", "fattened_fraction",
                                               "missing_fraction", "fattening_px")}


def jump_pixels(depth: np.ndarray, *, jump_m: float, gap_px: int = 3) -> np.ndarray:
    """``(H, W)`` bool: the pixels of depth discontinuities of ``depth`` (metres, NaN = none).

    Along x and along y, two valid pixels ``a`` and ``b`` up to ``gap_px`` apart (each pixel between them invalid
    or between their depths) make a jump when ``b - a`` differs by more than ``max(jump_m, 0.7 |b - a|)`` from the
    change the slope on each side predicts (the one-sided difference over two pixels just outside ``a`` and just
    outside ``b``, over the same distance; where neither side has one, a slope of 0); ``a``, ``b`` and the pixels
    between are marked. A plane at any angle, however steep its depth changes from pixel to pixel, has none
    (simtof's definition, session 10, which tested the mean of the two slopes: that marked pixels up to three
    beyond a step, whose one outer slope reached across it).

    >>> z = np.tile(np.r_[1.0 + 0.1 * np.arange(8), 3.0 + 0.1 * np.arange(8)], (3, 1))  # a slope, a step, a slope
    >>> jump_pixels(z, jump_m=0.1)[1].astype(int).tolist()
    [0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0]
    >>> int(jump_pixels(np.tile(200.0 / np.arange(40.0, 60.0)[:, None], (1, 5)), jump_m=0.1).sum())  # grazing floor
    0
    """
    z = np.asarray(depth, np.float64)
    return _jumps_along_x(z, jump_m, gap_px) | _jumps_along_x(z.T, jump_m, gap_px).T


def _jumps_along_x(z: np.ndarray, jump_m: float, gap_px: int) -> np.ndarray:
    h, w = z.shape
    p = np.pad(z, ((0, 0), (2, gap_px + 2)), constant_values=np.nan)  # p[:, j + 2] = z[:, j]
    out = np.zeros((h, w), bool)
    for g in range(1, gap_px + 1):
        a, b = p[:, 2:2 + w], p[:, 2 + g:2 + g + w]
        step = b - a
        with np.errstate(invalid="ignore"):
            thr = np.maximum(jump_m, 0.7 * np.abs(step))
            off = [np.abs(step - g * sl) > thr for sl in ((a - p[:, 0:w]) / 2, (p[:, 4 + g:4 + g + w] - b) / 2)]
        no_slope = np.isnan(p[:, 0:w] - a) & np.isnan(p[:, 4 + g:4 + g + w] - b)
        unexplained = np.where(no_slope, np.abs(step) > thr, (off[0] | np.isnan(p[:, 0:w])) & (off[1] | np.isnan(
            p[:, 4 + g:4 + g + w])))
        between = np.ones((h, w), bool)
        for k in range(1, g):
            m = p[:, 2 + k:2 + k + w]
            with np.errstate(invalid="ignore"):
                between &= ~np.isfinite(m) | ((m - np.fmin(a, b)) * (np.fmax(a, b) - m) >= 0)
        with np.errstate(invalid="ignore"):
            hit = np.isfinite(a) & np.isfinite(b) & between & unexplained
        for k in range(g + 1):
            out[:, k:] |= hit[:, :w - k]
    return out


def edge_errors(depth: np.ndarray, reference: np.ndarray, *, jump_m: float = 0.1, band_px: int = 2,
                tol_m: float | None = None) -> EdgeErrors:
    """Errors within ``band_px`` pixels of reference depth jumps larger than ``jump_m``: the reference pixels whose
    3x3 neighbourhood spans more than ``jump_m`` and that lie on a discontinuity (:func:`jump_pixels`). Beside a
    step on a grazing floor the 3x3 and band windows still see the floor's own slope.

    A measured pixel is *flying* when it lies between the near and far side of the jump (more
    than ``tol_m`` from both; default: 2 % of the depth), *fattened* when its reference is the
    far side but it reads the near side. ``fattening_px``: fattened background pixels per edge pixel.
    """
    ref = np.where(np.isfinite(reference), reference, 1e3).astype(np.float32)
    k = np.ones((3, 3), np.uint8)
    near, far = cv2.erode(ref, k), cv2.dilate(ref, k)
    edge = np.isfinite(reference) & (far - near > jump_m) & (far < 1e3)
    edge &= jump_pixels(reference, jump_m=jump_m)
    if not edge.any():
        return EdgeErrors(0, float("nan"), float("nan"), float("nan"), float("nan"))
    kb = np.ones((2 * band_px + 1, 2 * band_px + 1), np.uint8)
    band = cv2.dilate(edge.astype(np.uint8), kb).astype(bool) & np.isfinite(reference)
    z_near = cv2.erode(ref, kb)
    z_far = np.where(cv2.dilate(np.where(ref < 1e3, ref, 0).astype(np.float32), kb) > 0,
                     cv2.dilate(np.where(ref < 1e3, ref, 0).astype(np.float32), kb), np.nan)
    tol = 0.02 * reference if tol_m is None else np.full(reference.shape, tol_m, np.float32)
    meas = np.isfinite(depth) & band
    on_near = np.abs(depth - z_near) <= tol
    on_far = np.abs(depth - z_far) <= tol
    between = meas & ~on_near & ~on_far & (depth > z_near) & (depth < z_far)
    is_bg = band & (reference - z_near > jump_m / 2)
    fattened = meas & is_bg & on_near
    n_meas = max(int(meas.sum()), 1)
    return EdgeErrors(int(band.sum()), float(between.sum() / n_meas), float(fattened.sum() / max(int((meas & is_bg).sum()), 1)),
                      float(1.0 - meas.sum() / max(int(band.sum()), 1)), float(fattened.sum() / max(int(edge.sum()), 1)))


# ----------------------------------------------------------------------------- quantisation
def depth_steps(depth: np.ndarray, edges: np.ndarray, *, min_values: int = 20) -> np.ndarray:
    """Per depth bin, the median gap (metres) between consecutive distinct measured depths.

    With a disparity quantised to steps ``s`` px, gaps grow as ``z**2 * s / (f B)``; with
    depth stored in units ``u``, they cannot fall below ``u``.
    """
    z = np.asarray(depth, np.float64)
    z = z[np.isfinite(z)]
    out = np.full(len(edges) - 1, np.nan)
    for b in range(len(edges) - 1):
        u = np.unique(np.round(z[(z >= edges[b]) & (z < edges[b + 1])], 7))
        if u.size >= min_values:
            out[b] = float(np.median(np.diff(u)))
    return out
