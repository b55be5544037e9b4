"""Depth warping: a depth image of one camera re-rendered on another camera's image plane (eq. 30).

Pure numpy/OpenCV, no I/O. Used for the HQ depth onto the LQ depth image (the reference of the
aligned dataset) and for the HQ depth onto the HQ colour image (to lift colour features to 3D).

Algorithm (forward splatting with a z-buffer and first-order surface interpolation)
----------------------------------------------------------------------------------
For every source pixel ``p`` with depth ``d``:

1. Eq. 30: ``X = T_dst_src * pi_src^-1(p, d)``; ``(u, v) = pi_dst(X)`` with both cameras' lens
   distortion (the source rays are undistorted once per geometry, the destination projection
   applies the OpenCV distortion polynomial); ``w = 1 / Z_dst`` (inverse depth).
2. Surface continuity: two 4-neighbours belong to one surface when their source depths differ by
   at most ``edge_rel`` of the depth (default 3 %). A point whose two neighbours along one axis are
   both on other surfaces is a *flying pixel* (ToF mixed pixel) or a one-pixel sliver and is dropped.
3. Local plane: from the continuous neighbours (central differences, one-sided at edges) the
   Jacobian of ``(u, v)`` and the gradient of ``w`` on the source grid give ``dw/du, dw/dv`` on the
   destination image. Inverse depth is affine in the image for a plane, so extrapolating ``w`` to
   a nearby destination pixel centre is exact on planes (up to the destination distortion's second
   order over one pixel) -- no staircase error on slanted floors and walls.
4. Splatting: a point with continuous neighbours on all four sides covers the ``k x k`` block of
   destination pixels around it (``k = 2`` when the destination is up to ~1.7x finer, larger when
   finer still) within one source-grid step of it, so the splats of neighbouring points overlap and
   a continuous surface leaves no holes. Towards a discontinuous neighbour a point reaches only
   half way (the edge is assumed at the midpoint) and holds its depth along that axis: nothing is
   extrapolated past the last sample of a surface, and no value is ever a mix of two surfaces.
5. Z-buffer (``np.maximum.at`` on an int64 key): the nearest surface wins (to ~2 % of depth);
   among splats of that surface a fixed priority of the splat offset decides, so the choice does
   not depend on the noisy values (taking the nearest of several noisy values of one surface
   would bias the reference towards the camera).

Output: ``float32`` metres ``(H_dst, W_dst)``, NaN where no source surface lands (occlusion
shadows, outside the source's view, edges). Only the source rows/columns that can reach the
destination (for depths from ``min_depth_m`` on) are processed; steps 1-3 are vectorised numpy
over preallocated buffers (fresh memory costs page faults that would dominate the run time).
Steps 4-5 (the scatter with a z-test) run as one compiled loop over the points (``engine="numba"``,
the default) or vectorised with gathers and ``np.maximum.at`` (``engine="numpy"``); both give
the same result, the compiled loop in about half the time of the whole warp.
"""
from __future__ import annotations

import math
import sys
import threading

import numpy as np

from capture.camera import Intrinsics, Transform

DEFAULT_EDGE_REL = 0.03


class DepthWarper:
    """Warp depth images from ``K_src`` to ``K_dst`` through ``T_dst_src`` (precomputes the rays).

    Args:
        K_src: source depth camera (e.g. HQ depth, 512x424).
        K_dst: destination camera (e.g. LQ depth, 640x480).
        T_dst_src: maps source camera points into the destination camera frame, metres.
        edge_rel: relative depth jump that separates two surfaces (0.03 = 3 %).
        footprint: splat block size ``k``; ``None`` chooses it from the focal-length ratio.

    Example:
        >>> K = Intrinsics(8, 6, 10.0, 10.0, 3.5, 2.5)
        >>> w = DepthWarper(K, K, Transform.identity())
        >>> bool(np.allclose(w(np.full((6, 8), 2.0, np.float32)), 2.0))
        True
    """

    def __init__(self, K_src: Intrinsics, K_dst: Intrinsics, T_dst_src: Transform, *,
                 edge_rel: float = DEFAULT_EDGE_REL, footprint: int | None = None, min_depth_m: float = 0.2,
                 engine: str = "auto") -> None:
        if engine not in ("auto", "numba", "numpy"):
            raise ValueError(f"engine must be auto, numba or numpy, got {engine!r}")
        self.engine = ("numba" if _have_numba() else "numpy") if engine == "auto" else engine
        self.K_src, self.K_dst, self.T = K_src, K_dst, T_dst_src
        self.edge_rel = float(edge_rel)
        if footprint is None:
            ratio = max(K_dst.fx / K_src.fx, K_dst.fy / K_src.fy)
            footprint = max(2, int(math.ceil(ratio * 1.15)))
        self.k = int(footprint)
        self.r = self.k  # padding of the z-buffer, absorbs targets outside the image
        H, W = K_src.shape
        rays = K_src.ray_grid().reshape(-1, 3)  # undistorted source rays, z = 1
        a = rays @ T_dst_src.R.T  # X_dst = d * a + t
        self.crop = self._source_crop(a, min_depth_m)
        r0, r1, c0, c1 = self.crop
        self._a = [np.ascontiguousarray(a[:, i].reshape(H, W)[r0:r1, c0:c1], dtype=np.float32) for i in range(3)]
        self._t = [np.float32(x) for x in T_dst_src.t]
        Hd, Wd = K_dst.shape
        self._Wp = Wd + 2 * self.r
        self._Hp = Hd + 2 * self.r
        self._offsets = _offsets(self.k)
        self._dist = K_dst.dist_coeffs.astype(np.float32) if K_dst.has_distortion else None

    def _source_crop(self, a: np.ndarray, min_depth_m: float) -> tuple[int, int, int, int]:
        """Rows and columns of the source that can land on the destination image at any depth
        from ``min_depth_m`` to infinity (a pixel moves along a segment in the destination image
        between those two depths); the warp only processes this rectangle (plus one pixel)."""
        H, W = self.K_src.shape
        m = self.r + 2
        near = self.K_dst.project(a * min_depth_m + self.T.t)
        far = self.K_dst.project(np.where(a[:, 2:] > 1e-9, a, np.nan))  # direction only (t -> 0)
        lo = np.fmin(near, far)
        hi = np.fmax(near, far)
        hit = ((hi[:, 0] >= -m) & (lo[:, 0] <= self.K_dst.width - 1 + m)
               & (hi[:, 1] >= -m) & (lo[:, 1] <= self.K_dst.height - 1 + m)).reshape(H, W)
        if not hit.any():
            return 0, 1, 0, 1
        rows, cols = np.flatnonzero(hit.any(axis=1)), np.flatnonzero(hit.any(axis=0))
        return (max(0, rows[0] - 1), min(H, rows[-1] + 2), max(0, cols[0] - 1), min(W, cols[-1] + 2))

    # ------------------------------------------------------------------ forward map
    def forward_map(self, depth: np.ndarray):
        """Eq. 30 for every source pixel: destination ``u, v`` (px) and inverse depth ``w`` (1/m).

        Returns ``(u, v, w, valid)``, each ``(H_src, W_src)``; outside the source crop (pixels
        that cannot reach the destination image) ``u, v`` are NaN and ``w`` is 0; invalid points (no
        depth, behind the destination camera) have ``valid = False`` and meaningless values.
        """
        d = np.asarray(depth, dtype=np.float32)
        if d.shape != self.K_src.shape:
            raise ValueError(f"depth image is {d.shape[1]}x{d.shape[0]}, source camera is "
                             f"{self.K_src.width}x{self.K_src.height}")
        r0, r1, c0, c1 = self.crop
        u, v, w, valid = self._forward(np.ascontiguousarray(d[r0:r1, c0:c1]).ravel())
        out = []
        for arr, fill in ((u, np.nan), (v, np.nan), (w, 0.0), (valid, False)):
            full = np.full(d.shape, fill, arr.dtype)
            full[r0:r1, c0:c1] = arr.reshape(r1 - r0, c1 - c0)
            out.append(full)
        return tuple(out)

    def _forward(self, d: np.ndarray, ws: dict | None = None):
        ws = ws if ws is not None else self._workspace()
        ax, ay, az = (a.ravel() for a in self._a)
        tx, ty, tz = self._t
        f32 = np.float32
        Z, x, y, valid, dc = ws["Z"], ws["x"], ws["y"], ws["valid"], ws["t2"]
        # branch-free: no depth (NaN, <= 0) becomes 0, and every value stays finite
        np.fmax(d, f32(0), out=dc)
        np.multiply(dc, az, out=Z)
        Z += tz
        np.greater(Z, f32(1e-6), out=valid)
        valid &= dc > 0
        np.maximum(Z, f32(1e-6), out=Z)
        w = np.divide(f32(1), Z, out=Z)
        np.multiply(dc, ax, out=x)
        x += tx
        x *= w
        np.multiply(dc, ay, out=y)
        y += ty
        y *= w
        if self._dist is not None:
            np.clip(x, -4, 4, out=x)  # beyond any lens model's range; such points leave the image
            np.clip(y, -4, 4, out=y)
            xd, yd = _distort(x, y, self._dist)
            x[:], y[:] = xd, yd
        K = self.K_dst
        u = x
        u *= f32(K.fx)
        u += f32(K.cx)
        v = y
        v *= f32(K.fy)
        v += f32(K.cy)
        return u, v, w, valid

    # ------------------------------------------------------------------ the warp
    def __call__(self, depth: np.ndarray) -> np.ndarray:
        return self.warp(depth)

    def warp(self, depth: np.ndarray) -> np.ndarray:
        """Warp one source depth image ``(H_src, W_src)`` float32 metres (NaN = none) to the destination.

        Works on flat arrays: the x-neighbour of pixel ``k`` is ``k + 1`` (row ends masked), the
        y-neighbour ``k + W``; every step is a contiguous numpy operation into preallocated
        buffers (fresh memory costs page faults that would dominate the run time).
        """
        d2 = np.asarray(depth, dtype=np.float32)
        if d2.shape != self.K_src.shape:
            raise ValueError(f"depth image is {d2.shape[1]}x{d2.shape[0]}, source camera is "
                             f"{self.K_src.width}x{self.K_src.height}")
        r0, r1, c0, c1 = self.crop
        d2 = np.ascontiguousarray(d2[r0:r1, c0:c1])
        H, W = d2.shape
        N = H * W
        d = d2.ravel()
        ws = self._workspace()
        u, v, w, valid = self._forward(d, ws)
        f32 = np.float32
        cxp, cyp, gxp, gyp, t1, t2 = ws["cxp"], ws["cyp"], ws["gxp"], ws["gyp"], ws["t1"], ws["t2"]
        with np.errstate(invalid="ignore"):
            if not valid.all() and np.any(~valid & (d > 0)):  # behind the destination camera
                d = np.where(valid, d, f32(np.nan))
            # continuity of each pixel with its right (cx) and lower (cy) neighbour, 0/1 floats
            rel = f32(self.edge_rel)
            for c, a, b in ((cxp[1:N], d[1:], d[:-1]), (cyp[W:N], d[W:], d[:-W])):
                n = a.size
                dd, lim = t1[:n], t2[:n]
                np.subtract(a, b, out=dd)
                np.abs(dd, out=dd)
                np.minimum(a, b, out=lim)
                lim *= rel
                np.less_equal(dd, lim, out=c, casting="unsafe")
            cxp[1:N] *= ws["not_row_end"]
            # ... and the step must continue the slope of a neighbouring step (inverse depth is
            # linear along a plane): a mixed pixel close to one surface passes the jump test above
            # but breaks the slope on both sides, so it loses its links and is dropped
            tau = f32(self.edge_rel / 3)
            for c, e in ((cxp, 1), (cyp, W)):
                n = N - e
                step = np.subtract(w[e:], w[:-e], out=t1[:n])
                m = n - e
                dd = np.subtract(step[e:], step[:-e], out=t2[:m])  # pair (link L, link L + e)
                np.abs(dd, out=dd)
                pair = ws["pair"][:N]
                pair[:e] = False
                pair[N - e:] = False
                np.less_equal(dd, np.multiply(w[e:e + m], tau), out=pair[e:e + m])
                if e == 1:  # pairs that touch a link across a row end do not count
                    pair[1:N - 1] &= ws["row_link"][:-1]
                    pair[1:N - 1] &= ws["row_link"][1:]
                support = pair[0:n] | pair[e:N]  # link L = k + e (pixels k, k + e) has a pair on either side
                c[e:N] *= support
        # cxp[k] links pixels k-1 and k; cyp[k] links k-W and k
        if self.engine == "numba":  # steps 3-5 per point in one compiled loop
            Wp = self._Wp
            buf = ws["zkey"]
            buf.fill(EMPTY_KEY)
            prio = _priorities(self._offsets)
            A = np.array([o[0] for o in self._offsets], np.int64)
            B = np.array([o[1] for o in self._offsets], np.int64)
            P = np.array([prio[o] for o in self._offsets], np.int64)
            _point_kernel()(buf, u, v, w, cxp, cyp, valid, np.int64(W), np.float32(self.K_dst.width),
                            np.float32(self.K_dst.height), np.float32(self.k // 2 + 1), np.float32(2 * (self.k // 2)),
                            A, B, P, np.int64(Wp), np.int64(self.r))
            lo_half = 0 if sys.byteorder == "little" else 1
            wv = buf[:self._Hp * Wp].view(np.int32)[lo_half::2].view(f32)
            return np.divide(f32(1), wv).reshape(self._Hp, Wp)[self.r:-self.r, self.r:-self.r]
        cl, cr = cxp[0:N], cxp[1:N + 1]
        cu, cd = cyp[0:N], cyp[W:N + W]
        nx = np.add(cl, cr, out=ws["nx"])  # continuous neighbours along x: 0, 1, 2
        ny = np.add(cu, cd, out=ws["ny"])

        # Sums of the differences to the continuous neighbours (2x the central difference inside,
        # 1x the one-sided one at edges). Per point the x sums share one factor and the y sums
        # another; they cancel in J^-1 [wx, wy] below, so no division by the counts is needed.
        def sum_x(p, out):
            g = gxp[1:N]
            np.subtract(p[1:], p[:-1], out=g)
            g *= cxp[1:N]
            return np.add(gxp[0:N], gxp[1:N + 1], out=out)

        def sum_y(p, out):
            g = gyp[W:N]
            np.subtract(p[W:], p[:-W], out=g)
            g *= cyp[W:N]
            return np.add(gyp[0:N], gyp[W:N + W], out=out)

        ux, uy, vx, vy = sum_x(u, ws["ux"]), sum_y(u, ws["uy"]), sum_x(v, ws["vx"]), sum_y(v, ws["vy"])
        wx, wy = sum_x(w, ws["wx"]), sum_y(w, ws["wy"])
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
        ok &= valid
        ok &= nx > 0
        ok &= ny > 0  # flying pixels, one-pixel slivers, degenerate maps: dropped
        # Interior points reaching less than one source-grid step over +-1 destination pixel
        # (destination not coarser than the source there; J^-1 = 2 S^-1 for the sums S) cover
        # their k x k block unconditionally: the fast path, almost every point.
        reach = np.abs(vy, out=ws["reach"])
        reach += np.abs(uy, out=tmp)
        ry = np.abs(vx, out=t2[:N])
        ry += np.abs(ux, out=tmp)
        np.maximum(reach, ry, out=reach)
        reach *= 2 * (self.k // 2)  # |target - point| <= k/2 pixels
        fast = np.less(reach, adet, out=ws["fast"])
        nn = np.add(nx, ny, out=tmp)
        fast &= nn == 4
        fast &= ok
        # points whose block can touch the destination image
        Wd, Hd = self.K_dst.width, self.K_dst.height
        m = self.k // 2 + 1
        inside = (u > -m) & (u < Wd + m) & (v > -m) & (v < Hd + m)
        ok &= inside
        fast &= inside

        Wp = self._Wp
        trash = self._Hp * Wp  # this cell absorbs masked-out targets

        def splat_setup(sel, scratch=None):
            """Per selected point: fractions of (u, v), z-buffer index of (floor u, floor v), dw/du, dw/dv.

            With ``scratch`` (name -> preallocated array) the results live in it (no fresh memory)."""
            n = sel.size
            if scratch is None:
                scratch = {k: np.empty(n, np.intp if k == "ibase" else f32) for k in
                           ("su", "sv", "fu", "fv", "base", "idet", "sgu", "sgv", "ibase")}
            su, sv, fu, fv, base, idet, sgu, sgv, ibase = (scratch[k][:n] for k in
                                                            ("su", "sv", "fu", "fv", "base", "idet", "sgu", "sgv", "ibase"))
            np.take(u, sel, out=su)
            np.take(v, sel, out=sv)
            np.floor(su, out=fu)
            np.floor(sv, out=fv)
            su -= fu  # fraction u - floor(u) in [0, 1)
            sv -= fv
            np.multiply(fv, f32(Wp), out=base)  # flat z-buffer index of (fu, fv), exact in float32 (< 2**24)
            base += fu
            base += f32(self.r * Wp + self.r)
            np.copyto(ibase, base, casting="unsafe")
            np.take(det, sel, out=idet)
            np.divide(f32(1), idet, out=idet)
            np.take(gu, sel, out=sgu)
            sgu *= idet
            np.take(gv, sel, out=sgv)
            sgv *= idet
            return su, sv, ibase, sgu, sgv, idet

        # Z-buffer key (int64, the maximum wins): its high int32 holds the top bits of w's float32
        # pattern (positive floats sort like their bit patterns), so the nearest surface wins to
        # ~2 % of w, then a fixed priority of the splat's offset; its low int32 holds w itself.
        # Among splats of one surface the choice thus depends on geometry only, not on the noisy
        # values (keeping the largest of several noisy w would bias the reference towards the
        # camera). The empty key has high half -1 (below every splat) and w = NaN, so 1/w is NaN.
        buf = ws["zkey"]
        buf.fill(EMPTY_KEY)
        prio = _priorities(self._offsets)
        lo_half, hi_half = (0, 1) if sys.byteorder == "little" else (1, 0)

        def key(val, prio, k_=None, c=None):  # int64: high int32 = (w's top bits, priority), low int32 = w
            bits = val.view(np.int32)
            k_ = np.empty(bits.size, np.int64) if k_ is None else k_
            halves = k_.view(np.int32).reshape(-1, 2)
            halves[:, lo_half] = bits
            c = np.empty(bits.size, np.int32) if c is None else c
            np.right_shift(bits, 18, out=c)
            c <<= 8
            c |= prio
            halves[:, hi_half] = c
            return k_

        sel = np.flatnonzero(fast)
        n = sel.size
        if n:
            sc = ws["splat"]
            fru, frv, ibase, sgu, sgv, _ = splat_setup(sel, sc)
            base_w, val, idx, kk, cc = (sc[k][:n] for k in ("base_w", "val", "idx", "key", "c"))
            np.take(w, sel, out=base_w)
            np.multiply(sgu, fru, out=val)
            base_w -= val
            np.multiply(sgv, frv, out=val)
            base_w -= val  # w extrapolated on the local plane to the pixel (fu, fv)
            for a_, b_ in self._offsets:
                off = b_ * Wp + a_
                np.multiply(sgu, f32(a_), out=val)
                val += base_w
                if b_:
                    val += sgv * f32(b_) if b_ != 1 else sgv
                np.add(ibase, off, out=idx)
                np.maximum.at(buf, idx, key(val, prio[(a_, b_)], kk, cc))

        # The rest (edge points, and interior points of strongly compressed surfaces), few: a
        # pixel is covered when it lies within one grid step towards a continuous neighbour, or
        # half way (the edge assumed at the midpoint) towards a discontinuous one -- there with the
        # point's own depth, so nothing is extrapolated past the last sample of a surface.
        ok &= ~fast
        e = np.flatnonzero(ok)
        if e.size:  # all targets at once: arrays (k*k, n)
            efru, efrv, eidx, egu, egv, idet = splat_setup(e)
            enx, eny = nx[e], ny[e]
            eidet = idet * (enx * eny)  # undo the sums' factors: J = S / n
            ejxu, ejxv = vy[e] * eidet / eny, -uy[e] * eidet / eny
            ejyu, ejyv = -vx[e] * eidet / enx, ux[e] * eidet / enx
            lxp, lxm = 0.5 + 0.5 * cr[e], -0.5 - 0.5 * cl[e]
            lyp, lym = 0.5 + 0.5 * cd[e], -0.5 - 0.5 * cu[e]
            A = np.array([a_ for a_, _ in self._offsets], f32)[:, None]
            B = np.array([b_ for _, b_ in self._offsets], f32)[:, None]
            cu_, cv_ = A - efru, B - efrv  # target minus point, destination pixels (k*k, n)
            sx = ejxu * cu_ + ejxv * cv_
            sy = ejyu * cu_ + ejyv * cv_
            take = (sx < lxp) & (sx > lxm) & (sy < lyp) & (sy > lym)
            # beyond the last sample towards a discontinuous neighbour the depth is held constant
            # along that grid axis; along a continuous axis the local plane still applies
            keep_x = ~(((sx > 0) & (lxp < 1)) | ((sx < 0) & (lxm > -1)))
            keep_y = ~(((sy > 0) & (lyp < 1)) | ((sy < 0) & (lym > -1)))
            val = (wx[e] / enx) * (sx * keep_x)
            val += (wy[e] / eny) * (sy * keep_y)
            val += w[e]
            np.maximum(val, f32(1e-12), out=val)
            off = (B * Wp + A).astype(np.intp)
            idx = np.where(take, eidx + off, trash).ravel()
            p = np.repeat(np.array([prio[o] for o in self._offsets], np.int32), take.shape[1])
            np.maximum.at(buf, idx, key(val.ravel(), p))
        wv = buf[:trash].view(np.int32)[lo_half::2].view(f32)  # the low halves: w (NaN where nothing landed)
        out = np.divide(f32(1), wv).reshape(self._Hp, Wp)[self.r:-self.r, self.r:-self.r]
        return out

    def _workspace(self) -> dict:
        """Scratch arrays reused between calls (padded ones keep their zero borders); one set per thread."""
        local = self.__dict__.setdefault("_local", threading.local())
        ws = getattr(local, "ws", None)
        if ws is None:
            r0, r1, c0, c1 = self.crop
            H, W = r1 - r0, c1 - c0
            N = H * W
            f32 = np.float32
            not_row_end = np.ones((H, W), f32)
            not_row_end[:, -1] = 0
            ws = {"cxp": np.zeros(N + 1, f32), "cyp": np.zeros(N + W, f32), "gxp": np.zeros(N + 1, f32),
                  "pair": np.zeros(N, bool), "row_link": not_row_end.ravel()[:-1] > 0,
                  "gyp": np.zeros(N + W, f32), "not_row_end": not_row_end.ravel()[:-1].copy(),
                  "zkey": np.zeros(self._Hp * self._Wp + 2 * self._Wp + 2 * self.k + 2, np.int64),
                  "splat": {k: np.empty(N, t) for k, t in (
                      ("su", f32), ("sv", f32), ("fu", f32), ("fv", f32), ("base", f32), ("idet", f32), ("sgu", f32),
                      ("sgv", f32), ("ibase", np.intp), ("base_w", f32), ("val", f32), ("idx", np.intp),
                      ("key", np.int64), ("c", np.int32), ("wq", f32), ("wt", f32), ("wu0", f32), ("wv0", f32))}}
            for name in ("Z", "x", "y", "t1", "t2", "nx", "ny", "ux", "uy", "vx", "vy", "wx", "wy", "det", "adet",
                         "gu", "gv", "reach"):
                ws[name] = np.empty(N, f32)
            for name in ("valid", "ok", "fast"):
                ws[name] = np.empty(N, bool)
            local.ws = ws
        return ws


_KERNEL = []


def _have_numba() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:  # pragma: no cover - numba is a dependency
        return False
    return True


def _point_kernel():
    """Steps 3-5 of the warp (local plane, splats, z-buffer) as one compiled loop over the points.

    numba; the same rules, the same float32 arithmetic order and the same int64 keys as the numpy
    path of :meth:`DepthWarper.warp` (the tests check both against each other and against the
    per-pixel reference). The scatter with a z-test is a loop by nature: numpy can only do it with
    gathers and ``ufunc.at``, which cost more than the rest of the warp together.
    """
    if _KERNEL:
        return _KERNEL[0]
    import numba

    @numba.njit(cache=True, nogil=True)
    def kernel(buf, u, v, w, cxp, cyp, valid, W, Wd, Hd, m, reach_scale, A, B, P, Wp, r):
        f32 = np.float32
        N = u.size
        tmp = np.empty(1, np.float32)
        tmp_i = tmp.view(np.int32)
        for k in range(N):
            if not valid[k]:
                continue
            cl, cr, cu, cd = cxp[k], cxp[k + 1], cyp[k], cyp[k + W]
            nx = f32(cl + cr)
            ny = f32(cu + cd)
            if nx == 0 or ny == 0:  # flying pixel, one-pixel sliver
                continue
            if not (u[k] > -m and u[k] < Wd + m and v[k] > -m and v[k] < Hd + m):
                continue
            # sums of the differences to the continuous neighbours (as sum_x / sum_y)
            gl = f32(f32(u[k] - u[k - 1]) * cl) if k >= 1 else f32(0)
            gr = f32(f32(u[k + 1] - u[k]) * cr) if k + 1 < N else f32(0)
            ux = f32(gl + gr)
            gl = f32(f32(v[k] - v[k - 1]) * cl) if k >= 1 else f32(0)
            gr = f32(f32(v[k + 1] - v[k]) * cr) if k + 1 < N else f32(0)
            vx = f32(gl + gr)
            gl = f32(f32(w[k] - w[k - 1]) * cl) if k >= 1 else f32(0)
            gr = f32(f32(w[k + 1] - w[k]) * cr) if k + 1 < N else f32(0)
            wx = f32(gl + gr)
            gl = f32(f32(u[k] - u[k - W]) * cu) if k >= W else f32(0)
            gr = f32(f32(u[k + W] - u[k]) * cd) if k + W < N else f32(0)
            uy = f32(gl + gr)
            gl = f32(f32(v[k] - v[k - W]) * cu) if k >= W else f32(0)
            gr = f32(f32(v[k + W] - v[k]) * cd) if k + W < N else f32(0)
            vy = f32(gl + gr)
            gl = f32(f32(w[k] - w[k - W]) * cu) if k >= W else f32(0)
            gr = f32(f32(w[k + W] - w[k]) * cd) if k + W < N else f32(0)
            wy = f32(gl + gr)
            det = f32(f32(ux * vy) - f32(uy * vx))
            adet = abs(det)
            if not adet > f32(1e-6):
                continue
            gu = f32(f32(wx * vy) - f32(wy * vx))
            gv = f32(f32(wy * ux) - f32(wx * uy))
            reach = max(f32(abs(vy) + abs(uy)), f32(abs(vx) + abs(ux))) * reach_scale
            fast = reach < adet and nx + ny == 4
            fu = np.floor(u[k])
            fv = np.floor(v[k])
            fru = f32(u[k] - fu)
            frv = f32(v[k] - fv)
            base = np.int64(fv + r) * Wp + np.int64(fu + r)
            idet = f32(f32(1) / det)
            sgu = f32(gu * idet)
            sgv = f32(gv * idet)
            base_w = f32(f32(w[k] - f32(sgu * fru)) - f32(sgv * frv))
            if not fast:
                e_idet = f32(idet * f32(nx * ny))
                jxu = f32(f32(vy * e_idet) / ny)
                jxv = f32(f32(-uy * e_idet) / ny)
                jyu = f32(f32(-vx * e_idet) / nx)
                jyv = f32(f32(ux * e_idet) / nx)
                lxp = f32(0.5) + f32(0.5) * cr
                lxm = f32(-0.5) - f32(0.5) * cl
                lyp = f32(0.5) + f32(0.5) * cd
                lym = f32(-0.5) - f32(0.5) * cu
                gxw = f32(wx / nx)
                gyw = f32(wy / ny)
            for t in range(A.size):
                a = A[t]
                b = B[t]
                if fast:
                    val = f32(f32(sgu * f32(a)) + base_w)
                    if b != 0:
                        val = f32(val + f32(sgv * f32(b)))
                else:
                    cu_ = f32(f32(a) - fru)
                    cv_ = f32(f32(b) - frv)
                    sx = f32(f32(jxu * cu_) + f32(jxv * cv_))
                    sy = f32(f32(jyu * cu_) + f32(jyv * cv_))
                    if not (sx < lxp and sx > lxm and sy < lyp and sy > lym):
                        continue
                    kx = not ((sx > 0 and lxp < 1) or (sx < 0 and lxm > -1))
                    ky = not ((sy > 0 and lyp < 1) or (sy < 0 and lym > -1))
                    val = f32(gxw * f32(sx * f32(kx)))
                    val = f32(val + f32(gyw * f32(sy * f32(ky))))
                    val = f32(val + w[k])
                    if val < f32(1e-12):
                        val = f32(1e-12)
                tmp[0] = val
                bits = np.int64(tmp_i[0])
                key = (((bits >> 18) << 8 | P[t]) << 32) | bits
                idx = base + b * Wp + a
                if key > buf[idx]:
                    buf[idx] = key

    _KERNEL.append(kernel)
    return kernel


def _offsets(k: int) -> list[tuple[int, int]]:
    """Splat offsets (a, b) from the pixel (floor u, floor v) for block size ``k``."""
    r = range(-(k // 2) + 1, k // 2 + 1 + (k % 2))
    return [(a, b) for b in r for a in r]


def _priorities(offsets) -> dict:
    """Fixed z-buffer priority of each splat offset among splats of one surface (first offset highest)."""
    return {o: len(offsets) - i for i, o in enumerate(offsets)}


#: the z-buffer's empty cell: high int32 -1 (below every splat), low int32 the bits of a float32 NaN
EMPTY_KEY = int(np.array([0x7FC00000, -1] if sys.byteorder == "little" else [-1, 0x7FC00000], np.int32).view(np.int64)[0])


def _zkey(w: float, priority: int) -> tuple[int, int, int]:
    """The z-buffer order of one splat, as the vectorised warp's int64 key orders it."""
    bits = int(np.float32(w).view(np.int32))
    return (bits >> 18, priority, bits)


def _distort(x: np.ndarray, y: np.ndarray, k: np.ndarray):
    """OpenCV distortion (k1, k2, p1, p2, k3, k4, k5, k6) on normalised coordinates, float32."""
    k1, k2, p1, p2, k3, k4, k5, k6 = (np.float32(c) for c in k)
    xy = x * y
    x2 = x * x
    y2 = y * y
    r2 = x2 + y2
    radial = k3 * r2
    radial += k2
    radial *= r2
    radial += k1
    radial *= r2
    radial += 1
    if k4 or k5 or k6:
        den = k6 * r2
        den += k5
        den *= r2
        den += k4
        den *= r2
        den += 1
        radial /= den
    xd = x * radial
    xd += (2 * p1) * xy
    xd += p2 * (r2 + 2 * x2)
    yd = y * radial
    yd += p1 * (r2 + 2 * y2)
    yd += (2 * p2) * xy
    return xd, yd


def warp_depth(depth_src: np.ndarray, K_src: Intrinsics, K_dst: Intrinsics, T_dst_src: Transform, *,
               edge_rel: float = DEFAULT_EDGE_REL) -> np.ndarray:
    """One-off :class:`DepthWarper` call; for many frames build the warper once."""
    return DepthWarper(K_src, K_dst, T_dst_src, edge_rel=edge_rel)(depth_src)


# ---------------------------------------------------------------------------------------------
# Slow references, for tests and the benchmark's comparison.
def warp_depth_loop(depth_src: np.ndarray, K_src: Intrinsics, K_dst: Intrinsics, T_dst_src: Transform, *,
                    edge_rel: float = DEFAULT_EDGE_REL, footprint: int | None = None) -> np.ndarray:
    """The algorithm of :class:`DepthWarper` written as a per-pixel Python loop (slow, float64).

    Each rule is spelled out per point, without the vectorised version's shortcuts (flat
    arrays, summed differences, the fast path's reach bound, the source crop); the test suite
    checks the vectorised warp against it.
    """
    H, W = K_src.shape
    Hd, Wd = K_dst.shape
    d = np.asarray(depth_src, dtype=np.float64)
    if footprint is None:
        ratio = max(K_dst.fx / K_src.fx, K_dst.fy / K_src.fy)
        footprint = max(2, int(math.ceil(ratio * 1.15)))
    k = footprint
    offsets = _offsets(k)
    prio = _priorities(offsets)
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

    def jump_ok(i0, j0, i1, j1):  # both valid, depth jump at most edge_rel of the nearer
        if not (0 <= i0 < H and 0 <= j0 < W and 0 <= i1 < H and 0 <= j1 < W):
            return False
        a, b = d[i0, j0], d[i1, j1]
        return bool(w[i0, j0] > 0 and w[i1, j1] > 0 and abs(b - a) <= edge_rel * min(a, b))

    def cont(i0, j0, i1, j1):  # ... and the step continues the slope of the step before or after it
        if not jump_ok(i0, j0, i1, j1):
            return False
        di, dj = i1 - i0, j1 - j0
        step = w[i1, j1] - w[i0, j0]
        for (ia, ja), (ib, jb), (ic, jc) in (((i0 - di, j0 - dj), (i0, j0), (i0, j0)),
                                            ((i1, j1), (i1 + di, j1 + dj), (i1, j1))):
            if 0 <= ia < H and 0 <= ja < W and 0 <= ib < H and 0 <= jb < W and w[ia, ja] > 0 and w[ib, jb] > 0:
                if abs(step - (w[ib, jb] - w[ia, ja])) <= edge_rel / 3 * w[ic, jc]:
                    return True
        return False

    zbuf = np.zeros((Hd, Wd))
    zkey = {}
    for i in range(H):
        for j in range(W):
            if w[i, j] <= 0:
                continue
            grads, conts = [], []
            for (di, dj) in ((0, 1), (1, 0)):  # x, then y
                n, acc, c = 0, np.zeros(3), []
                for s in (-1, 1):
                    ii, jj = i + s * di, j + s * dj
                    c.append(cont(i, j, ii, jj))
                    if c[-1]:
                        acc += s * np.array([u[ii, jj] - u[i, j], v[ii, jj] - v[i, j], w[ii, jj] - w[i, j]])
                        n += 1
                grads.append((n, acc / max(n, 1)))
                conts.append(c)  # [minus side, plus side]
            (nx, gx), (ny, gy) = grads
            if nx == 0 or ny == 0:
                continue  # flying pixel / one-pixel sliver
            J = np.array([[gx[0], gy[0]], [gx[1], gy[1]]])  # d(u, v) / d(source x, y)
            if abs(np.linalg.det(J)) <= 1e-6 / (nx * ny):
                continue
            Jinv = np.linalg.inv(J)
            lim = {(0, -1): 1.0 if conts[0][0] else 0.5, (0, 1): 1.0 if conts[0][1] else 0.5,
                   (1, -1): 1.0 if conts[1][0] else 0.5, (1, 1): 1.0 if conts[1][1] else 0.5}
            fu, fv = math.floor(u[i, j]), math.floor(v[i, j])
            for a, b in offsets:
                if True:
                    c = np.array([fu + a - u[i, j], fv + b - v[i, j]])
                    delta = Jinv @ c  # source-grid offset of the target pixel
                    inside, val = True, w[i, j]
                    for ax, g in ((0, gx), (1, gy)):
                        side = 1 if delta[ax] > 0 else -1
                        if not (abs(delta[ax]) < lim[(ax, side)]):
                            inside = False
                        if lim[(ax, side)] == 1:  # towards a continuous neighbour: local plane
                            val += g[2] * delta[ax]
                    tu, tv = fu + a, fv + b
                    if inside and 0 <= tu < Wd and 0 <= tv < Hd:
                        kv = _zkey(max(val, 1e-12), prio[(a, b)])
                        if (tv, tu) not in zkey or kv > zkey[(tv, tu)]:
                            zkey[(tv, tu)] = kv
                            zbuf[tv, tu] = val
    out = np.full((Hd, Wd), np.nan, np.float32)
    out[zbuf > 0] = (1.0 / zbuf[zbuf > 0]).astype(np.float32)
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


def register_color(color: np.ndarray, depth: np.ndarray, K_depth: Intrinsics, K_color: Intrinsics,
                   T_color_depth: Transform) -> np.ndarray:
    """Colour resampled onto the depth image: each depth pixel's 3D point projected into the colour
    camera and sampled (bilinear). ``(H_depth, W_depth, 3)`` uint8; black where there is no depth."""
    P = K_depth.depth_to_points(depth).reshape(-1, 3)
    uv = K_color.project(T_color_depth.apply(P)).astype(np.float32)
    bad = ~np.all(np.isfinite(uv), axis=1)
    uv[bad] = -1e4
    mx = uv[:, 0].reshape(K_depth.shape)
    my = uv[:, 1].reshape(K_depth.shape)
    import cv2

    return cv2.remap(color, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
