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
   ``edge_reach`` of a step (0.5, the default: the edge is assumed at the midpoint) and holds its
   depth along that axis: nothing is extrapolated past the last sample of a surface, and no value
   is ever a mix of two surfaces. Where both axis neighbours of a quadrant are on the point's
   surface but the diagonal neighbour is linked to neither (a diagonal silhouette, or a missing
   sample), the samples cover a triangle, not the square: past ``|dx| + |dy| < 1 + edge_reach``
   grid steps the splat fills no pixel on its own (:func:`align.warp_splat.diagonal_cuts`), so a
   near surface does not claim the far surface's corner one pixel past a diagonal silhouette; where
   another splat lands there it still takes part in the z-test (:func:`align.warp_splat.merge_cut`:
   the far samples the source saw just past the silhouette stay hidden behind the near surface).
   ``edge_reach=0`` claims only what the samples cover: the reference of the aligned dataset uses it
   (see :mod:`align.reference_edges` for why).
5. Z-buffer (``np.maximum.at`` on an int64 key): the nearest surface wins (to ~2 % of depth);
   among splats of that surface a fixed priority of the splat offset decides, so the choice does
   not depend on the noisy values (taking the nearest of several noisy values of one surface
   would bias the reference towards the camera).

Output: ``float32`` metres ``(H_dst, W_dst)``, NaN where no source surface lands (occlusion
shadows, outside the source's view, edges). Only the source rows/columns that can reach the
destination (for depths from ``min_depth_m`` on) are processed; steps 1-3 are vectorised numpy
over preallocated buffers (fresh memory costs page faults that would dominate the run time).
Steps 3-5 (the local plane, the scatter with a z-test) run as one compiled loop over the points
(``engine="numba"``, the default, :mod:`align.warp_numba`) or vectorised with gathers and
``np.maximum.at`` (``engine="numpy"``, :mod:`align.warp_numpy`); both give the same result, the
compiled loop in about half the time of the whole warp. What they share (the points, the z-buffer
and its keys) is in :mod:`align.warp_splat`; slow per-pixel references in :mod:`align.warp_reference`.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from align.errors import OptionError, WarpInputError
from align.warp_numba import have_numba, splat_numba
from align.warp_numpy import splat_numpy
from align.warp_reference import DEFAULT_EDGE_REL, default_footprint, warp_depth_loop, warp_depth_naive_loop
from align.warp_splat import SourcePoints, SplatGrid, splat_offsets

__all__ = ["DEFAULT_EDGE_REL", "CropMotion", "DepthWarper", "register_color", "warp_depth", "warp_depth_loop",
           "warp_depth_naive_loop"]


@dataclass(frozen=True)
class CropMotion:
    """The source points' motion as :meth:`DepthWarper.warp` adds it, over the warper's source crop
    (:attr:`DepthWarper.crop`, row-major, ``N`` points): ``dst`` ``(3, N)`` float32 metres, the motion
    rotated into the destination camera frame (``R m``, each row contiguous), and ``dz`` ``(N,)``
    float32 metres, its depth component in the source frame (``m_z``, the continuity test's).
    :meth:`DepthWarper.crop_motion` makes it from an image of motions; :mod:`align._flow_kernel`
    writes it directly."""

    dst: np.ndarray
    dz: np.ndarray


class DepthWarper:
    """Warp depth images from ``K_src`` to ``K_dst`` through ``T_dst_src`` (precomputes the rays).

    Args:
        K_src: source depth camera (e.g. HQ depth, 512x424).
        K_dst: destination camera (e.g. LQ depth, 640x480).
        T_dst_src: maps source camera points into the destination camera frame, metres.
        edge_rel: relative depth jump that separates two surfaces (0.03 = 3 %).
        footprint: splat block size ``k``; ``None`` chooses it from the focal-length ratio.
        edge_reach: how far a surface reaches past its last sample towards another surface, in
            source-grid steps, ``[0, 1)`` (step 4 above).

    Example:
        >>> from capture.camera import Intrinsics, Transform
        >>> K = Intrinsics(8, 6, 10.0, 10.0, 3.5, 2.5)
        >>> w = DepthWarper(K, K, Transform.identity())
        >>> bool(np.allclose(w(np.full((6, 8), 2.0, np.float32)), 2.0))
        True
    """

    def __init__(self, K_src: Intrinsics, K_dst: Intrinsics, T_dst_src: Transform, *,
                 edge_rel: float = DEFAULT_EDGE_REL, footprint: int | None = None, min_depth_m: float = 0.2,
                 engine: str = "auto", edge_reach: float = 0.5) -> None:
        if engine not in ("auto", "numba", "numpy"):
            raise OptionError(f"warp engine must be auto, numba or numpy, got {engine!r}")
        if not 0.0 <= edge_reach < 1.0:
            raise OptionError(f"edge reach must be in [0, 1) source-grid steps, got {edge_reach!r}",
                              option="edge_reach")
        self.engine = ("numba" if have_numba() else "numpy") if engine == "auto" else engine
        self.K_src, self.K_dst, self.T = K_src, K_dst, T_dst_src
        self.edge_rel = float(edge_rel)
        self.k = int(footprint if footprint is not None else default_footprint(K_src, K_dst))
        self.r = self.k  # padding of the z-buffer, absorbs targets outside the image
        H, W = K_src.shape
        rays = K_src.ray_grid().reshape(-1, 3)  # undistorted source rays, z = 1
        a = rays @ T_dst_src.R.T  # X_dst = d * a + t
        self.crop = self._source_crop(a, min_depth_m)
        r0, r1, c0, c1 = self.crop
        self._a = [np.ascontiguousarray(a[:, i].reshape(H, W)[r0:r1, c0:c1], dtype=np.float32) for i in range(3)]
        self._t = [np.float32(x) for x in T_dst_src.t]
        self.grid = SplatGrid(k=self.k, r=self.r, width=K_dst.width, height=K_dst.height,
                              offsets=tuple(splat_offsets(self.k)), edge_reach=float(edge_reach))
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
    def forward_map(self, depth: np.ndarray, *, motion=None):
        """Eq. 30 for every source pixel: destination ``u, v`` (px) and inverse depth ``w`` (1/m).

        Returns ``(u, v, w, valid)``, each ``(H_src, W_src)``; outside the source crop (pixels
        that cannot reach the destination image) ``u, v`` are NaN and ``w`` is 0; invalid points (no
        depth, behind the destination camera) have ``valid = False`` and meaningless values. ``motion``:
        as :meth:`warp`'s (the points moved first), ``None``: not moved.
        """
        d = self._check_shape(depth)
        r0, r1, c0, c1 = self.crop
        if motion is not None and not isinstance(motion, CropMotion):
            motion = self.crop_motion(motion)
        return self._full_map(d.shape, self._forward(np.ascontiguousarray(d[r0:r1, c0:c1]).ravel(), None,
                                                     None if motion is None else motion.dst))

    def _full_map(self, shape: tuple, fwd: tuple) -> tuple:
        """:meth:`_forward`'s flat crop ``(u, v, w, valid)`` laid out on the whole source image (:meth:`forward_map`)."""
        r0, r1, c0, c1 = self.crop
        out = []
        for arr, fill in zip(fwd, (np.nan, np.nan, 0.0, False)):
            full = np.full(shape, fill, arr.dtype)
            full[r0:r1, c0:c1] = arr.reshape(r1 - r0, c1 - c0)
            out.append(full)
        return tuple(out)

    def _forward(self, d: np.ndarray, ws: dict | None = None, motion=None):
        """Step 1 on the flat crop; ``motion``: ``(mx, my, mz)`` flat, the source points'
        displacement rotated into the destination frame (``R m``), metres, or ``None``."""
        ws = ws if ws is not None else self._workspace()
        ax, ay, az = (a.ravel() for a in self._a)
        tx, ty, tz = self._t
        f32 = np.float32
        Z, x, y, valid, dc = ws["Z"], ws["x"], ws["y"], ws["valid"], ws["t2"]
        # branch-free: no depth (NaN, <= 0) becomes 0, and every value stays finite
        np.fmax(d, f32(0), out=dc)
        np.multiply(dc, az, out=Z)
        Z += tz
        if motion is not None:
            Z += motion[2]
        np.greater(Z, f32(1e-6), out=valid)
        valid &= dc > 0
        np.maximum(Z, f32(1e-6), out=Z)
        w = np.divide(f32(1), Z, out=Z)
        np.multiply(dc, ax, out=x)
        x += tx
        if motion is not None:
            x += motion[0]
        x *= w
        np.multiply(dc, ay, out=y)
        y += ty
        if motion is not None:
            y += motion[1]
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
    def __call__(self, depth: np.ndarray, *, motion=None) -> np.ndarray:
        return self.warp(depth, motion=motion)

    def warp(self, depth: np.ndarray, *, motion=None) -> np.ndarray:
        """Warp one source depth image ``(H_src, W_src)`` float32 metres (NaN = none) to the destination
        (:meth:`_warp`)."""
        return self._warp(depth, motion=motion)[0]

    def warp_with_map(self, depth: np.ndarray, *, motion=None) -> tuple[np.ndarray, tuple]:
        """``(warp(depth, motion=motion), forward_map(depth, motion=motion))`` from one forward projection."""
        return self._warp(depth, motion=motion, keep_map=True)

    def _warp(self, depth: np.ndarray, *, motion=None, keep_map: bool = False) -> tuple[np.ndarray, tuple | None]:
        """The warp of one source depth image ``(H_src, W_src)`` float32 metres (NaN = none) to the destination,
        and with ``keep_map`` its :meth:`forward_map` (else None).

        Steps 1-2 here (flat arrays over the source crop: the x-neighbour of pixel ``k`` is
        ``k + 1``, row ends masked, the y-neighbour ``k + W``), steps 3-5 in the engine.

        ``motion``: ``(H_src, W_src, 3)`` displacement of each source point in the source camera
        frame, metres (:mod:`align.motion_flow`: the scene's motion between the source frame and
        the destination's instant), or the same as a :class:`CropMotion`; the points move, the
        surface links stay those of the source grid. ``None``: no motion (the default).
        """
        d2 = self._check_shape(depth)
        shape = d2.shape
        r0, r1, c0, c1 = self.crop
        d2 = np.ascontiguousarray(d2[r0:r1, c0:c1])
        ws = self._workspace()
        d = d2.ravel()
        if motion is not None and not isinstance(motion, CropMotion):
            motion = self.crop_motion(motion)
        if motion is not None and motion.dz.shape != d.shape:
            raise WarpInputError(f"motion covers {motion.dz.size} source points, the warp's crop {d.size}")
        u, v, w, valid = self._forward(d, ws, None if motion is None else motion.dst)
        fmap = self._full_map(shape, (u, v, w, valid)) if keep_map else None
        if motion is not None:
            d = d + motion.dz  # the moved points' source depth: the continuity test's input
        with np.errstate(invalid="ignore"):
            if not valid.all() and np.any(~valid & (d > 0)):  # behind the destination camera
                d = np.where(valid, d, np.float32(np.nan))
            _continuity(d, w, ws, W=d2.shape[1], edge_rel=self.edge_rel)
        pts = SourcePoints(u=u, v=v, w=w, valid=valid, cxp=ws["cxp"], cyp=ws["cyp"], W=d2.shape[1])
        if self.engine == "numba":
            return splat_numba(pts, self.grid, ws["zkey"]), fmap
        return splat_numpy(pts, self.grid, ws), fmap

    def crop_motion(self, motion: np.ndarray) -> "CropMotion":
        """``motion`` ``(H_src, W_src, 3)`` (source camera frame, metres) laid out as :meth:`warp` uses it."""
        r0, r1, c0, c1 = self.crop
        m = np.asarray(motion, np.float32)
        if m.shape != (*self.K_src.shape, 3):
            raise WarpInputError(f"motion is {m.shape}, the source camera needs {(*self.K_src.shape, 3)}")
        m = m[r0:r1, c0:c1].reshape(-1, 3)
        return CropMotion(dst=self.T.R.astype(np.float32) @ m.T, dz=np.ascontiguousarray(m[:, 2]))

    def _check_shape(self, depth: np.ndarray) -> np.ndarray:
        d = np.asarray(depth, dtype=np.float32)
        if d.shape != self.K_src.shape:
            raise WarpInputError(f"depth image is {d.shape[1]}x{d.shape[0]}, source camera is "
                                 f"{self.K_src.width}x{self.K_src.height}")
        return d

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
                  "zkey": np.zeros(2 * self.grid.zbuffer_size(), np.int64),  # z-buffer, then the cut splats
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


def _continuity(d: np.ndarray, w: np.ndarray, ws: dict, *, W: int, edge_rel: float) -> None:
    """Step 2 on the flat source grid of width ``W``: ``ws["cxp"][k]`` (pixels ``k - 1, k``) and
    ``ws["cyp"][k]`` (pixels ``k - W, k``) become 1 where the two belong to one surface, else 0.

    A link holds when the depth jump is at most ``edge_rel`` of the nearer depth, and the step in
    inverse depth continues the slope of a neighbouring step (inverse depth is linear along a
    plane): a mixed pixel close to one surface passes the jump test but breaks the slope on both
    sides, so it loses its links and is dropped.
    """
    N = d.size
    f32 = np.float32
    cxp, cyp, t1, t2 = ws["cxp"], ws["cyp"], ws["t1"], ws["t2"]
    rel = f32(edge_rel)
    for c, a, b in ((cxp[1:N], d[1:], d[:-1]), (cyp[W:N], d[W:], d[:-W])):
        n = a.size
        dd, lim = t1[:n], t2[:n]
        np.subtract(a, b, out=dd)
        np.abs(dd, out=dd)
        np.minimum(a, b, out=lim)
        lim *= rel
        np.less_equal(dd, lim, out=c, casting="unsafe")
    cxp[1:N] *= ws["not_row_end"]
    tau = f32(edge_rel / 3)
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
               edge_rel: float = DEFAULT_EDGE_REL, edge_reach: float = 0.5) -> np.ndarray:
    """One-off :class:`DepthWarper` call; for many frames build the warper once."""
    return DepthWarper(K_src, K_dst, T_dst_src, edge_rel=edge_rel, edge_reach=edge_reach)(depth_src)


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
