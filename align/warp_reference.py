"""Slow references of the depth warp, for the tests and the benchmark's comparison.

:func:`warp_depth_loop` is the algorithm of :class:`align.warp.DepthWarper` written as a
per-pixel Python loop in float64, each rule spelled out per point, without the vectorised
version's shortcuts (flat arrays, summed differences, the fast path's reach bound, the source
crop); the test suite checks both engines against it. :func:`warp_depth_naive_loop` is the
straightforward splat (nearest pixel, z-test), the benchmark's baseline for speed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from align.warp_splat import splat_offsets, splat_priorities, zkey
from capture.camera import Intrinsics, Transform

DEFAULT_EDGE_REL = 0.03


def default_footprint(K_src: Intrinsics, K_dst: Intrinsics) -> int:
    """Splat block size ``k``: 2 when the destination is up to ~1.7x finer, larger when finer still."""
    ratio = max(K_dst.fx / K_src.fx, K_dst.fy / K_src.fy)
    return max(2, int(math.ceil(ratio * 1.15)))


@dataclass
class _Grid:
    """Per source pixel (float64): depth ``d``, destination ``u, v`` and inverse depth ``w`` (0 = invalid)."""

    d: np.ndarray
    u: np.ndarray
    v: np.ndarray
    w: np.ndarray
    edge_rel: float
    dst_shape: tuple = (0, 0)

    def inside(self, i, j) -> bool:
        H, W = self.d.shape
        return 0 <= i < H and 0 <= j < W

    def jump_ok(self, i0, j0, i1, j1) -> bool:
        """Both valid, depth jump at most edge_rel of the nearer."""
        if not (self.inside(i0, j0) and self.inside(i1, j1)):
            return False
        a, b, w = self.d[i0, j0], self.d[i1, j1], self.w
        return bool(w[i0, j0] > 0 and w[i1, j1] > 0 and abs(b - a) <= self.edge_rel * min(a, b))

    def cont(self, i0, j0, i1, j1) -> bool:
        """... and the step continues the slope of the step before or after it."""
        if not self.jump_ok(i0, j0, i1, j1):
            return False
        w = self.w
        di, dj = i1 - i0, j1 - j0
        step = w[i1, j1] - w[i0, j0]
        for (ia, ja), (ib, jb), (ic, jc) in (((i0 - di, j0 - dj), (i0, j0), (i0, j0)),
                                            ((i1, j1), (i1 + di, j1 + dj), (i1, j1))):
            if self.inside(ia, ja) and self.inside(ib, jb) and w[ia, ja] > 0 and w[ib, jb] > 0:
                if abs(step - (w[ib, jb] - w[ia, ja])) <= self.edge_rel / 3 * w[ic, jc]:
                    return True
        return False

    def gradients(self, i, j):
        """Per axis (x, then y): (continuous neighbours, mean difference [du, dv, dw]) and the
        continuity towards the minus and the plus side."""
        grads, conts = [], []
        for (di, dj) in ((0, 1), (1, 0)):
            n, acc, c = 0, np.zeros(3), []
            for s in (-1, 1):
                ii, jj = i + s * di, j + s * dj
                c.append(self.cont(i, j, ii, jj))
                if c[-1]:
                    acc += s * np.array([self.u[ii, jj] - self.u[i, j], self.v[ii, jj] - self.v[i, j],
                                         self.w[ii, jj] - self.w[i, j]])
                    n += 1
            grads.append((n, acc / max(n, 1)))
            conts.append(c)  # [minus side, plus side]
        return grads, conts


def _project_all(d, K_src: Intrinsics, K_dst: Intrinsics, T_dst_src: Transform, edge_rel: float) -> _Grid:
    H, W = K_src.shape
    u = np.full((H, W), np.nan)
    v = np.full((H, W), np.nan)
    w = np.zeros((H, W))
    for i in range(H):
        for j in range(W):
            if not d[i, j] > 0:
                continue
            X = T_dst_src.apply(K_src.unproject(np.array([[j, i]], float), np.array([d[i, j]])))[0]
            if X[2] <= 1e-6:
                continue
            uv = K_dst.project(X[None])[0]
            u[i, j], v[i, j], w[i, j] = uv[0], uv[1], 1.0 / X[2]
    return _Grid(d, u, v, w, edge_rel)


def _splat(g: _Grid, i: int, j: int, offsets, prio, zkeys, zcut, edge_reach: float) -> None:
    """Splat point (i, j) onto the z-buffer (``zkeys``: (row, col) -> (key, w)); the splats past the triangle
    of a quadrant cut at the diagonal go to ``zcut`` (they count only where another splat landed)."""
    grads, conts = g.gradients(i, j)
    (nx, gx), (ny, gy) = grads
    if nx == 0 or ny == 0:
        return  # flying pixel / one-pixel sliver
    J = np.array([[gx[0], gy[0]], [gx[1], gy[1]]])  # d(u, v) / d(source x, y)
    if abs(np.linalg.det(J)) <= 1e-6 / (nx * ny):
        return
    Jinv = np.linalg.inv(J)
    lim = {(ax, s): 1.0 if conts[ax][(s + 1) // 2] else edge_reach for ax in (0, 1) for s in (-1, 1)}
    # a quadrant whose axis neighbours are linked but whose diagonal neighbour is linked to neither:
    # the samples cover the triangle, |dx| + |dy| < 1 + edge_reach (align.warp_splat.diagonal_cuts)
    cut = {(sx, sy): lim[(0, sx)] == 1 and lim[(1, sy)] == 1
           and not (g.cont(i, j + sx, i + sy, j + sx) or g.cont(i + sy, j, i + sy, j + sx))
           for sx in (-1, 1) for sy in (-1, 1)}
    fu, fv = math.floor(g.u[i, j]), math.floor(g.v[i, j])
    Hd, Wd = g.dst_shape
    for a, b in offsets:
        delta = Jinv @ np.array([fu + a - g.u[i, j], fv + b - g.v[i, j]])  # source-grid offset of the target
        inside, val = True, g.w[i, j]
        for ax, (_, gr) in enumerate(grads):
            side = 1 if delta[ax] > 0 else -1
            if not (abs(delta[ax]) < lim[(ax, side)]):
                inside = False
            if lim[(ax, side)] == 1:  # towards a continuous neighbour: local plane
                val += gr[2] * delta[ax]
        beyond = cut[(1 if delta[0] > 0 else -1, 1 if delta[1] > 0 else -1)] and \
            abs(delta[0]) + abs(delta[1]) >= 1 + edge_reach
        tu, tv = fu + a, fv + b
        if inside and 0 <= tu < Wd and 0 <= tv < Hd:
            kv = zkey(max(val, 1e-12), prio[(a, b)])
            keys = zcut if beyond else zkeys   # past the triangle: fills nothing on its own
            if (tv, tu) not in keys or kv > keys[(tv, tu)][0]:
                keys[(tv, tu)] = (kv, val)


def warp_depth_loop(depth_src: np.ndarray, K_src: Intrinsics, K_dst: Intrinsics, T_dst_src: Transform, *,
                    edge_rel: float = DEFAULT_EDGE_REL, footprint: int | None = None,
                    edge_reach: float = 0.5) -> np.ndarray:
    """The algorithm of :class:`align.warp.DepthWarper` as a per-pixel Python loop (slow, float64).

    Returns ``(H_dst, W_dst)`` float32 metres, NaN where nothing lands.
    """
    H, W = K_src.shape
    k = footprint if footprint is not None else default_footprint(K_src, K_dst)
    offsets = splat_offsets(k)
    prio = splat_priorities(offsets)
    g = _project_all(np.asarray(depth_src, dtype=np.float64), K_src, K_dst, T_dst_src, edge_rel)
    g.dst_shape = K_dst.shape
    zkeys: dict = {}
    zcut: dict = {}
    for i in range(H):
        for j in range(W):
            if g.w[i, j] > 0:
                _splat(g, i, j, offsets, prio, zkeys, zcut, edge_reach)
    out = np.full(K_dst.shape, np.nan, np.float32)
    for (tv, tu), (kv, val) in zkeys.items():
        if (tv, tu) in zcut and zcut[(tv, tu)][0] > kv:
            val = zcut[(tv, tu)][1]
        if val > 0:
            out[tv, tu] = np.float32(1.0 / val)
    return out


def warp_depth_naive_loop(depth_src: np.ndarray, K_src: Intrinsics, K_dst: Intrinsics,
                          T_dst_src: Transform) -> np.ndarray:
    """The straightforward per-pixel loop: project each source pixel, nearest pixel, z-buffer.

    No hole filling and no interpolation; the benchmark's baseline for speed, not a reference.
    """
    H, W = K_src.shape
    Hd, Wd = K_dst.shape
    out = np.full((Hd, Wd), np.inf)
    R, t = T_dst_src.R, T_dst_src.t
    rays = K_src.ray_grid()
    for i in range(H):
        for j in range(W):
            z = depth_src[i, j]
            if not z > 0:
                continue
            X = R @ (rays[i, j] * z) + t
            if X[2] <= 0:
                continue
            uv = K_dst.project(X[None])[0]
            tu, tv = int(round(uv[0])), int(round(uv[1]))
            if 0 <= tu < Wd and 0 <= tv < Hd and X[2] < out[tv, tu]:
                out[tv, tu] = X[2]
    out[~np.isfinite(out)] = np.nan
    return out.astype(np.float32)
