"""Exact neighbourhood searches behind the plane-fit RMSE (:mod:`bench.plane_fit`): pure numpy/scipy, no I/O.

Two searches over the points of a depth image (``z * (xn, yn, 1)`` with the camera's normalised
ray coordinates), both exact:

* **Radius neighbourhood sums** of every reference point: count, sums of ``q - p`` and of their
  products (the ten numbers a least-squares plane needs), over the points ``q`` with
  ``|q - p| <= r``;
* **closest point** of another cloud (the denoised one) to every scored point, exact ties going
  to the lowest row-major pixel index.

On an organised cloud without lens distortion (``Grid``) neighbours are searched in the image: a
point ``q`` with ``|q - p| <= d`` lies within ``f * d * sqrt(1 + x_n^2) / (z_p - d)`` pixels of ``p``,
so a per-pixel window bound makes the search exact. Ring-1 sums use shifted-array arithmetic on
row strips (:func:`strip_sums`); wider windows visit pixel offsets in increasing normalised length,
each only from the pixels whose reach covers it (:func:`deep_sums`). The closest-point search widens
rings until a lower bound on every unvisited pixel's distance proves the best one found
(:func:`strip_closest`, :func:`deep_closest`). Pixels whose bound exceeds the window cap
``GRID_CAP`` fall back to scipy's KD-tree (:func:`ball_pairs`, :func:`closest_kdtree`), which also
serves any cloud (``method="kdtree"``).

Dense work runs on a thread pool kept for the process (:func:`run_threads`; numpy releases the GIL);
results do not depend on the number of threads.
"""
from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache

import numpy as np
from scipy.spatial import cKDTree

from capture.camera import Intrinsics

GRID_CAP = 8          # widest pixel window (Chebyshev radius) the grid search visits before the KD-tree fallback
_SENTINEL = 1.0e6      # invalid pixels sit at distinct far-away positions (1e6 m apart), never within any radius
STRIP_ELEMENTS = 16384  # elements per row strip of the grid search (a few arrays of this size stay in L2 cache)


@lru_cache(maxsize=8)
def rays(intrinsics: Intrinsics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normalised ray coordinates ``xn, yn`` ``(H, W)`` and ``s = sqrt(1 + xn^2 + yn^2)`` (read-only)."""
    grid = intrinsics.ray_grid()
    xn, yn = np.ascontiguousarray(grid[..., 0]), np.ascontiguousarray(grid[..., 1])
    s = np.sqrt(1.0 + xn * xn + yn * yn)
    for a in (xn, yn, s):
        a.setflags(write=False)
    return xn, yn, s


def ring(k: int) -> list[tuple[int, int]]:
    """Pixel offsets ``(dv, du)`` at Chebyshev distance exactly ``k``."""
    if k == 0:
        return [(0, 0)]
    out = [(dv, du) for dv in (-k, k) for du in range(-k, k + 1)]
    out += [(dv, du) for du in (-k, k) for dv in range(-k + 1, k)]
    return out


def half_ring(k: int) -> list[tuple[int, int]]:
    """One offset of each opposite pair of :func:`ring` (``dv > 0``, or ``dv == 0`` and ``du > 0``)."""
    return [(dv, du) for dv, du in ring(k) if dv > 0 or (dv == 0 and du > 0)]


@lru_cache(maxsize=8)
def deep_groups(fx: float, fy: float) -> tuple[tuple[float, tuple[tuple[int, int], ...]], ...]:
    """Offsets of Chebyshev distance 2.._GRID_CAP grouped by their normalised length
    ``e = sqrt((du / fx)^2 + (dv / fy)^2)``, in increasing ``e``."""
    groups: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for k in range(2, GRID_CAP + 1):
        for dv, du in ring(k):
            groups.setdefault((abs(dv), abs(du)), []).append((dv, du))
    out = [(float(np.hypot(a[1] / fx, a[0] / fy)), tuple(v)) for a, v in groups.items()]
    return tuple(sorted(out))


def beyond_cap(K: Intrinsics) -> float:
    """Smallest normalised length of an offset outside the grid's window cap."""
    return (GRID_CAP + 1) / max(K.fx, K.fy)


class Grid:
    """Flat padded image layout: pixel ``(v, u)`` sits at ``(v + pad) * Wp + u + pad``.

    Invalid pixels (and the border) hold far-away points, each at its own position
    (``_SENTINEL`` metres apart), so no distance test ever pairs them. Shifting an image by a pixel
    offset is then a contiguous slice; the dense work is split into row strips that stay in cache
    and run on threads (numpy releases the GIL).
    """

    def __init__(self, shape: tuple[int, int], pad: int = GRID_CAP) -> None:
        self.H, self.W = shape
        self.pad, self.Wp = pad, self.W + 2 * pad
        self.size = (self.H + 2 * pad) * self.Wp
        self.base = pad * self.Wp
        rows = max(4, STRIP_ELEMENTS // self.Wp)
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


def crop_box(vv: np.ndarray, uu: np.ndarray, shape: tuple[int, int]) -> tuple[slice, slice]:
    """Bounding box of the pixels ``(vv, uu)`` grown by the window cap: every pixel a window search
    from them can visit lies inside."""
    return (slice(max(int(vv.min()) - GRID_CAP, 0), min(int(vv.max()) + GRID_CAP + 1, shape[0])),
            slice(max(int(uu.min()) - GRID_CAP, 0), min(int(uu.max()) + GRID_CAP + 1, shape[1])))


_POOLS: dict[int, ThreadPoolExecutor] = {}
_POOL_LOCK = threading.Lock()


def run_threads(fn, items, threads: int) -> list:
    """``[fn(*it) for it in items]``, on up to ``threads`` threads of a pool kept for the process
    (starting threads per call costs more than small strips take)."""
    if threads <= 1 or len(items) <= 1:
        return [fn(*it) for it in items]
    with _POOL_LOCK:
        pool = _POOLS.get(threads)
        if pool is None:
            pool = _POOLS[threads] = ThreadPoolExecutor(threads, thread_name_prefix=f"bench-plane-fit-{threads}")
    return list(pool.map(lambda it: fn(*it), items))


def chunks(n: int, parts: int) -> list[tuple[int, int]]:
    edges = np.linspace(0, n, max(1, min(parts, n)) + 1).astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]


PRODUCTS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def strip_sums(G: Grid, X: list[np.ndarray], r2: float, v0: int, v1: int) -> np.ndarray:
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
    for dv, du in half_ring(1):
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
        for k, (a, b) in enumerate(PRODUCTS):
            np.multiply(t[a], d[b], out=tmp)
            acc[4 + k, :L] += tmp
            acc[4 + k, off:off + L] += tmp
    return acc


def deep_sums(G: Grid, X: list[np.ndarray], sums: np.ndarray, *, fp: np.ndarray, pos: np.ndarray,
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
                for j, (a, b) in enumerate(PRODUCTS):
                    sums[4 + j, ph] += dh[a] * dh[b]


def strip_closest(G: Grid, Xr: list[np.ndarray], Xq: list[np.ndarray], fp: np.ndarray, *, v0: int,
                  v1: int) -> tuple[np.ndarray, np.ndarray]:
    """Closest denoised point among the 3x3 window of each scored pixel ``fp`` (flat padded, rows ``v0..v1``).

    Returns ``(squared distance, flat index of that point)``.
    """
    L = (v1 - v0) * G.Wp
    s0 = G.start(v0)
    offsets = sorted(G.offset(dv, du) for dv, du in ring(0) + ring(1))   # argmin: ties -> lowest pixel index
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


def deep_closest(G: Grid, Xr, Xq, fp, *, bd, qi, z, s, groups, beyond: float) -> np.ndarray:
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


def closest_kdtree(cloud: np.ndarray, queries: np.ndarray, threads: int) -> np.ndarray:
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


def ball_pairs(tree: cKDTree, queries: np.ndarray, r: float, self_index: np.ndarray):
    """Directed pairs (query position, tree index) within ``r``, excluding each query's own point."""
    lists = tree.query_ball_point(queries, r, return_sorted=False)
    lengths = np.fromiter((len(x) for x in lists), dtype=np.int64, count=len(lists))
    j = np.fromiter((k for x in lists for k in x), dtype=np.int64, count=int(lengths.sum()))
    i = np.repeat(np.arange(len(lists)), lengths)
    keep = j != self_index[i]
    return i[keep], j[keep]


def neighbour_sums_pairs(pts, pos, i, j):
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
    for k, (a, b) in enumerate(PRODUCTS):
        out[4 + k] = np.bincount(i, weights=d[:, a] * d[:, b], minlength=m)
    return out
