"""The warp's vectorised engine: steps 3-5 (local plane, splats, z-buffer) in numpy.

Pure numpy, no I/O; the same rules, float32 arithmetic order and int64 keys as the compiled
engine (:mod:`align.warp_numba`). Every step works on flat arrays over preallocated buffers
(``ws``, from :meth:`align.warp.DepthWarper._workspace`), the scatter through ``np.maximum.at``.

* Local plane (step 3): per point, sums of the differences to its continuous neighbours (2x the
  central difference inside, 1x the one-sided one at edges) of ``u, v, w``; per point the x sums
  share one factor and the y sums another; they cancel in ``J^-1 [wx, wy]``, so no division by
  the counts is needed. ``[gu, gv] = [wx, wy] J^-1`` is the gradient of ``w`` on the destination.
* Fast path (step 4): interior points (all four diagonal neighbours linked through an axis
  neighbour too, :func:`align.warp_splat.diagonal_cuts`) reaching less than one source-grid step over +-1
  destination pixel (destination not coarser than the source there; ``J^-1 = 2 S^-1`` for the
  sums ``S``) cover their ``k x k`` block unconditionally -- almost every point.
* Edge path: the rest (edge points, and interior points of strongly compressed surfaces), few: a
  pixel is covered when it lies within one grid step towards a continuous neighbour, or within the
  edge reach (``grid.edge_reach`` of a step; 0.5: the edge assumed at the midpoint) towards a
  discontinuous one -- there with the point's own depth, so nothing is extrapolated past the
  last sample of a surface; in a quadrant cut at the diagonal, past ``|dx| + |dy| < 1 + reach``, a
  splat fills nothing on its own (``merge_cut``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from align.warp_splat import EMPTY_KEY, HI_HALF, LO_HALF, SourcePoints, SplatGrid, diagonal_cuts, merge_cut

f32 = np.float32


@dataclass
class _Plane:
    """Step 3 per point: the sums of differences ``ux .. wy``, their determinant and ``gu, gv``
    (times the determinant), neighbour counts ``nx, ny`` and which points can be splatted."""

    ux: np.ndarray
    uy: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    wx: np.ndarray
    wy: np.ndarray
    det: np.ndarray
    gu: np.ndarray
    gv: np.ndarray
    nx: np.ndarray
    ny: np.ndarray
    ok: np.ndarray
    fast: np.ndarray
    buf: np.ndarray  # the z-buffer (int64 keys)
    cut: np.ndarray  # the splats of quadrants cut at the diagonal (merge_cut)


def splat_numpy(pts: SourcePoints, grid: SplatGrid, ws: dict) -> np.ndarray:
    """Steps 3-5 for every valid point. Returns the destination depth ``(height, width)`` float32
    metres, NaN where nothing landed."""
    pl = _local_plane(pts, grid, ws)
    pl.buf.fill(EMPTY_KEY)
    pl.cut.fill(EMPTY_KEY)
    _splat_fast(pts, grid, pl, ws)
    _splat_edges(pts, grid, pl)
    merge_cut(pl.buf, pl.cut)
    return grid.depth_from_keys(pl.buf)


def _sum_x(p, pts: SourcePoints, gxp, out):
    N, cxp = pts.N, pts.cxp
    g = gxp[1:N]
    np.subtract(p[1:], p[:-1], out=g)
    g *= cxp[1:N]
    return np.add(gxp[0:N], gxp[1:N + 1], out=out)


def _sum_y(p, pts: SourcePoints, gyp, out):
    N, W, cyp = pts.N, pts.W, pts.cyp
    g = gyp[W:N]
    np.subtract(p[W:], p[:-W], out=g)
    g *= cyp[W:N]
    return np.add(gyp[0:N], gyp[W:N + W], out=out)


def _local_plane(pts: SourcePoints, grid: SplatGrid, ws: dict) -> _Plane:
    N, W = pts.N, pts.W
    u, v, w = pts.u, pts.v, pts.w
    cxp, cyp, gxp, gyp, t1, t2 = pts.cxp, pts.cyp, ws["gxp"], ws["gyp"], ws["t1"], ws["t2"]
    nx = np.add(cxp[0:N], cxp[1:N + 1], out=ws["nx"])  # continuous neighbours along x: 0, 1, 2
    ny = np.add(cyp[0:N], cyp[W:N + W], out=ws["ny"])
    ux, uy = _sum_x(u, pts, gxp, ws["ux"]), _sum_y(u, pts, gyp, ws["uy"])
    vx, vy = _sum_x(v, pts, gxp, ws["vx"]), _sum_y(v, pts, gyp, ws["vy"])
    wx, wy = _sum_x(w, pts, gxp, ws["wx"]), _sum_y(w, pts, gyp, ws["wy"])
    tmp = t1[:N]
    det = np.multiply(ux, vy, out=ws["det"])
    det -= np.multiply(uy, vx, out=tmp)
    adet = np.abs(det, out=ws["adet"])
    ok = np.greater(adet, f32(1e-6), out=ws["ok"])
    # gradient of w on the destination image: [gu, gv] = [wx, wy] J^-1
    gu = np.multiply(wx, vy, out=ws["gu"])
    gu -= np.multiply(wy, vx, out=tmp)
    gv = np.multiply(wy, ux, out=ws["gv"])
    gv -= np.multiply(wx, uy, out=tmp)
    ok &= pts.valid
    ok &= nx > 0
    ok &= ny > 0  # flying pixels, one-pixel slivers, degenerate maps: dropped
    reach = np.abs(vy, out=ws["reach"])
    reach += np.abs(uy, out=tmp)
    ry = np.abs(vx, out=t2[:N])
    ry += np.abs(ux, out=tmp)
    np.maximum(reach, ry, out=reach)
    reach *= 2 * (grid.k // 2)  # |target - point| <= k/2 pixels
    fast = np.less(reach, adet, out=ws["fast"])
    nn = np.add(nx, ny, out=tmp)
    fast &= nn == 4
    fast &= ok
    m = grid.margin  # points whose block can touch the destination image
    inside = (u > -m) & (u < grid.width + m) & (v > -m) & (v < grid.height + m)
    ok &= inside
    fast &= inside
    cand = np.flatnonzero(fast)
    fast[cand[diagonal_cuts(pts, cand) != 0]] = False  # a diagonal neighbour on another surface: edge path
    ok &= ~fast  # ok: the edge path's points from here on
    return _Plane(ux=ux, uy=uy, vx=vx, vy=vy, wx=wx, wy=wy, det=det, gu=gu, gv=gv, nx=nx, ny=ny, ok=ok, fast=fast,
                  buf=ws["zkey"][:grid.zbuffer_size()], cut=ws["zkey"][grid.zbuffer_size():2 * grid.zbuffer_size()])


def _splat_setup(sel, pts: SourcePoints, grid: SplatGrid, pl: _Plane, scratch=None):
    """Per selected point: fractions of (u, v), z-buffer index of (floor u, floor v), dw/du, dw/dv.

    With ``scratch`` (name -> preallocated array) the results live in it (no fresh memory)."""
    n = sel.size
    if scratch is None:
        scratch = {k: np.empty(n, np.intp if k == "ibase" else f32) for k in
                   ("su", "sv", "fu", "fv", "base", "idet", "sgu", "sgv", "ibase")}
    su, sv, fu, fv, base, idet, sgu, sgv, ibase = (scratch[k][:n] for k in
                                                    ("su", "sv", "fu", "fv", "base", "idet", "sgu", "sgv", "ibase"))
    Wp = grid.padded_width
    np.take(pts.u, sel, out=su)
    np.take(pts.v, sel, out=sv)
    np.floor(su, out=fu)
    np.floor(sv, out=fv)
    su -= fu  # fraction u - floor(u) in [0, 1)
    sv -= fv
    np.multiply(fv, f32(Wp), out=base)  # flat z-buffer index of (fu, fv), exact in float32 (< 2**24)
    base += fu
    base += f32(grid.r * Wp + grid.r)
    np.copyto(ibase, base, casting="unsafe")
    np.take(pl.det, sel, out=idet)
    np.divide(f32(1), idet, out=idet)
    np.take(pl.gu, sel, out=sgu)
    sgu *= idet
    np.take(pl.gv, sel, out=sgv)
    sgv *= idet
    return su, sv, ibase, sgu, sgv, idet


def _key(val, prio, k_=None, c=None):
    """int64 z-buffer keys: high int32 = (w's top bits, priority), low int32 = w."""
    bits = val.view(np.int32)
    k_ = np.empty(bits.size, np.int64) if k_ is None else k_
    halves = k_.view(np.int32).reshape(-1, 2)
    halves[:, LO_HALF] = bits
    c = np.empty(bits.size, np.int32) if c is None else c
    np.right_shift(bits, 18, out=c)
    c <<= 8
    c |= prio
    halves[:, HI_HALF] = c
    return k_


def _splat_fast(pts: SourcePoints, grid: SplatGrid, pl: _Plane, ws: dict) -> None:
    """The fast path: each point's whole ``k x k`` block on its local plane."""
    sel = np.flatnonzero(pl.fast)
    n = sel.size
    if not n:
        return
    Wp, prio, buf = grid.padded_width, grid.priorities(), pl.buf
    sc = ws["splat"]
    fru, frv, ibase, sgu, sgv, _ = _splat_setup(sel, pts, grid, pl, sc)
    base_w, val, idx, kk, cc = (sc[k][:n] for k in ("base_w", "val", "idx", "key", "c"))
    np.take(pts.w, sel, out=base_w)
    np.multiply(sgu, fru, out=val)
    base_w -= val
    np.multiply(sgv, frv, out=val)
    base_w -= val  # w extrapolated on the local plane to the pixel (fu, fv)
    for a_, b_ in grid.offsets:
        off = b_ * Wp + a_
        np.multiply(sgu, f32(a_), out=val)
        val += base_w
        if b_:
            val += sgv * f32(b_) if b_ != 1 else sgv
        np.add(ibase, off, out=idx)
        np.maximum.at(buf, idx, _key(val, prio[(a_, b_)], kk, cc))


def _splat_edges(pts: SourcePoints, grid: SplatGrid, pl: _Plane) -> None:
    """The edge path: all targets of all edge points at once, arrays ``(k*k, n)``."""
    e = np.flatnonzero(pl.ok)
    if not e.size:
        return
    N, W = pts.N, pts.W
    cl, cr = pts.cxp[0:N], pts.cxp[1:N + 1]
    cu, cd = pts.cyp[0:N], pts.cyp[W:N + W]
    Wp, prio = grid.padded_width, grid.priorities()
    efru, efrv, eidx, egu, egv, idet = _splat_setup(e, pts, grid, pl)
    enx, eny = pl.nx[e], pl.ny[e]
    eidet = idet * (enx * eny)  # undo the sums' factors: J = S / n
    ejxu, ejxv = pl.vy[e] * eidet / eny, -pl.uy[e] * eidet / eny
    ejyu, ejyv = -pl.vx[e] * eidet / enx, pl.ux[e] * eidet / enx
    h = f32(grid.edge_reach)
    hold = f32(1) - h
    lxp, lxm = h + hold * cr[e], -h - hold * cl[e]
    lyp, lym = h + hold * cd[e], -h - hold * cu[e]
    A = np.array([a_ for a_, _ in grid.offsets], f32)[:, None]
    B = np.array([b_ for _, b_ in grid.offsets], f32)[:, None]
    cu_, cv_ = A - efru, B - efrv  # target minus point, destination pixels (k*k, n)
    sx = ejxu * cu_ + ejxv * cv_
    sy = ejyu * cu_ + ejyv * cv_
    take = (sx < lxp) & (sx > lxm) & (sy < lyp) & (sy > lym)
    # a quadrant whose diagonal neighbour is on another surface: the triangle only (diagonal_cuts)
    bit = (sx <= 0).astype(np.int64) + 2 * (sy <= 0).astype(np.int64)
    cut = ((diagonal_cuts(pts, e)[None, :] >> bit) & 1).astype(bool)
    cut &= (np.abs(sx) + np.abs(sy)) >= f32(1) + h
    # beyond the last sample towards a discontinuous neighbour the depth is held constant
    # along that grid axis; along a continuous axis the local plane still applies
    keep_x = ~(((sx > 0) & (lxp < 1)) | ((sx < 0) & (lxm > -1)))
    keep_y = ~(((sy > 0) & (lyp < 1)) | ((sy < 0) & (lym > -1)))
    val = (pl.wx[e] / enx) * (sx * keep_x)
    val += (pl.wy[e] / eny) * (sy * keep_y)
    val += pts.w[e]
    np.maximum(val, f32(1e-12), out=val)
    off = (B * Wp + A).astype(np.intp)
    trash = grid.padded_height * Wp  # this cell absorbs masked-out targets
    p = np.repeat(np.array([prio[o] for o in grid.offsets], np.int32), take.shape[1])
    keys = _key(val.ravel(), p)
    for buf, sel in ((pl.buf, take & ~cut), (pl.cut, take & cut)):
        np.maximum.at(buf, np.where(sel, eidx + off, trash).ravel(), keys)
