"""Motion between unsynchronised frames, by scene flow: the HQ frame's points moved to the LQ instant
along the optical flow of the HQ colour images (issue 12).

Pure numpy/OpenCV, no I/O. Like :mod:`align.motion` it reads no LQ depth and no LQ colour: the
reference is not pulled towards the input scored against it.

The model
---------
The pair's own HQ frame ``o`` and the other HQ frame ``x`` around the LQ instant (``frac``: the LQ
instant's share of the way from ``o`` to ``x``, ``alpha`` or ``1 - alpha`` of :func:`align.motion.bracket`).
Over one frame period every point moves at constant velocity (first order in time, as
:mod:`align.motion` assumes for depth), so at the LQ instant it sits at ``P + frac (P_x - P)``,
where ``P_x`` is the same point in frame ``x``. :class:`SceneFlow` finds ``P_x - P`` per sample:

1. each depth sample of ``o`` is projected into its own HQ colour image (``T_color_depth``);
2. the dense optical flow from ``o``'s colour image to ``x``'s (OpenCV's DIS, ultrafast preset, on
   grey images reduced to ``flow_scale``) carries it to its colour position in ``x``; the same
   displacement, scaled by the focal-length ratio, gives its depth pixel ``q`` in ``x`` (the
   colour-to-depth parallax changes with the point's depth change only, millimetres);
3. ``P_x`` is ``x``'s sample at ``q``, unprojected. It is trusted when its depth is within
   ``max_jump_m`` of the point's (a flow that lands on another surface is not the point's motion);
   untrusted samples take the mean motion of the trusted ones within ``fill_px`` (else none).

:func:`moved_reference` then warps ``o`` with the points moved by ``frac (P_x - P)``
(:meth:`align.warp.DepthWarper.warp`'s ``motion``): silhouettes land where they are at the LQ
instant, limbs included that moved more than their own width (which choosing per pixel between the
two frames, :mod:`align.motion`, cannot recover). Disocclusions the own frame did not see stay holes.

Measured (``perf/reference_motion.py``, seeds 1-3 at 7 ms apart, scale 1, strict edges): see the
closing note of session 5 and ``docs/worklog``.
"""
from __future__ import annotations

import cv2
import numpy as np

from align.errors import WarpInputError

#: grey images for the flow are the HQ colour images reduced by this factor
DEFAULT_FLOW_SCALE = 0.5
#: a flow target whose depth differs from the point's by more than this is another surface (m)
DEFAULT_MAX_JUMP_M = 0.15
#: untrusted samples take the mean motion of trusted ones within this many depth pixels
DEFAULT_FILL_PX = 7


def flow_image(color: np.ndarray, *, scale: float = DEFAULT_FLOW_SCALE) -> np.ndarray:
    """The grey image the flow runs on: ``color`` ``(H, W, 3)`` RGB uint8 (or ``(H, W)`` grey) reduced
    by ``scale``, uint8."""
    g = color if color.ndim == 2 else cv2.cvtColor(np.ascontiguousarray(color), cv2.COLOR_RGB2GRAY)
    if scale == 1:
        return np.ascontiguousarray(g, np.uint8)
    return cv2.resize(g, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)


class ColorFlow:
    """Dense optical flow between two grey images (OpenCV DIS, ultrafast preset; one per thread)."""

    def __init__(self) -> None:
        import threading

        self._local = threading.local()

    def __call__(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Flow ``(h, w, 2)`` float32 pixels of ``a``'s pixels into ``b``."""
        dis = getattr(self._local, "dis", None)
        if dis is None:
            dis = self._local.dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST)
        if a.shape != b.shape:
            raise WarpInputError(f"flow images differ in size: {a.shape} and {b.shape}")
        return dis.calc(a, b, None)


class SceneFlow:
    """Each sample's motion from an HQ frame ``o`` to another frame ``x`` (the module docstring's
    steps 1-3) for one HQ rig; the rays and the colour projection are set up once.

    Args:
        K_depth, K_color, T_color_depth: the HQ depth and colour cameras (colour from depth, metres).
        flow_scale, max_jump_m, fill_px: the module constants' meaning; ``None``: their defaults.
    """

    def __init__(self, K_depth, K_color, T_color_depth, *, flow_scale: float | None = None,
                 max_jump_m: float | None = None, fill_px: int | None = None) -> None:
        f32 = np.float32
        self.K_depth, self.K_color, self.T = K_depth, K_color, T_color_depth
        self.flow_scale = f32(DEFAULT_FLOW_SCALE if flow_scale is None else flow_scale)
        self.max_jump_m = f32(DEFAULT_MAX_JUMP_M if max_jump_m is None else max_jump_m)
        self.fill_px = int(DEFAULT_FILL_PX if fill_px is None else fill_px)
        rays = K_depth.ray_grid().astype(f32)  # (H, W, 3), z = 1, undistorted
        self._rx, self._ry = np.ascontiguousarray(rays[..., 0]), np.ascontiguousarray(rays[..., 1])
        H, W = K_depth.height, K_depth.width
        self._yy, self._xx = (a.astype(f32) for a in np.mgrid[0:H, 0:W])
        self._R, self._t = T_color_depth.R.astype(f32), T_color_depth.t.astype(f32)

    def _colour_position(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each sample's position on the reduced flow image (x, y), -1e4 where it has no depth."""
        R, t, s = self._R, self._t, self.flow_scale
        X, Y = d * self._rx, d * self._ry
        Xc, Yc, Zc = (R[k, 0] * X + R[k, 1] * Y + R[k, 2] * d + t[k] for k in range(3))
        Kc = self.K_color
        if Kc.has_distortion:
            uv = Kc.project(np.stack([Xc, Yc, Zc], axis=-1).reshape(-1, 3)).reshape(*d.shape, 2).astype(np.float32)
            u, v = uv[..., 0], uv[..., 1]
        else:
            with np.errstate(divide="ignore", invalid="ignore"):
                u = Xc / Zc * np.float32(Kc.fx) + np.float32(Kc.cx)
                v = Yc / Zc * np.float32(Kc.fy) + np.float32(Kc.cy)
        u, v = (u + np.float32(0.5)) * s - np.float32(0.5), (v + np.float32(0.5)) * s - np.float32(0.5)
        return np.nan_to_num(u, nan=-1e4), np.nan_to_num(v, nan=-1e4)

    def motion(self, depth_o: np.ndarray, depth_x: np.ndarray, flow: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(motion, trusted)`` of frame ``o``'s samples towards frame ``x``.

        Args:
            depth_o, depth_x: HQ depth frames ``(H, W)`` float32 metres (NaN = none).
            flow: :class:`ColorFlow` of ``o``'s grey colour image into ``x``'s (:func:`flow_image`).
        Returns:
            ``motion`` ``(H, W, 3)`` float32 metres in ``o``'s depth camera frame (0 where neither the
            sample nor a trusted neighbour within ``fill_px`` has one) and ``trusted`` ``(H, W)`` bool.
        """
        d = np.asarray(depth_o, np.float32)
        if d.shape != self._xx.shape or np.shape(depth_x) != d.shape:
            raise WarpInputError(f"depth frames are {d.shape} and {np.shape(depth_x)}, the HQ depth camera "
                                 f"{self._xx.shape}")
        m, trusted = self._steps(d, np.asarray(depth_x, np.float32), flow)
        return _fill(m, trusted, self.fill_px), trusted

    def _steps(self, d: np.ndarray, depth_x: np.ndarray, flow: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Steps 1-3, vectorised: the motion (0 where not trusted) and which samples are trusted."""
        mx, my = self._colour_position(d)
        duv = cv2.remap(flow, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=(np.nan, np.nan))
        Kd, Kc, s = self.K_depth, self.K_color, self.flow_scale
        qx = self._xx + duv[..., 0] * np.float32(Kd.fx / Kc.fx / s)
        qy = self._yy + duv[..., 1] * np.float32(Kd.fy / Kc.fy / s)
        qx, qy = np.nan_to_num(qx, nan=-1e4), np.nan_to_num(qy, nan=-1e4)
        dq = cv2.remap(np.asarray(depth_x, np.float32), qx, qy, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                       borderValue=np.nan)
        with np.errstate(invalid="ignore"):
            trusted = np.abs(dq - d) <= self.max_jump_m  # False where either is NaN
        f32 = np.float32
        if Kd.has_distortion:  # the ray through q
            rxq, ryq = (cv2.remap(r, qx, qy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE) for r in (self._rx, self._ry))
        else:
            rxq, ryq = (qx - f32(Kd.cx)) / f32(Kd.fx), (qy - f32(Kd.cy)) / f32(Kd.fy)
        planes = [np.where(trusted, rxq * dq - d * self._rx, f32(0)), np.where(trusted, ryq * dq - d * self._ry, f32(0)),
                  np.where(trusted, dq - d, f32(0))]
        return np.stack(planes, axis=-1).astype(np.float32, copy=False), trusted


def _fill(m: np.ndarray, trusted: np.ndarray, fill_px: int) -> np.ndarray:
    """Untrusted samples of ``m`` (H, W, 3), 0 there: the mean motion of trusted ones within ``fill_px``
    (a box), else 0."""
    if fill_px <= 0:
        return m
    k = (2 * fill_px + 1, 2 * fill_px + 1)
    den = cv2.boxFilter(trusted.astype(np.float32), -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT)
    scale = np.where(trusted, np.float32(0), np.float32(1) / np.maximum(den, np.float32(1)))
    num = cv2.boxFilter(m, -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT)
    num *= scale[..., None]
    num += m  # trusted: m; untrusted (m = 0): the neighbours' mean
    return num


def moved_reference(warper, depth_o: np.ndarray, motion: np.ndarray, frac: float) -> np.ndarray:
    """Frame ``o`` warped by ``warper`` (:class:`align.warp.DepthWarper`) with every point moved by
    ``frac`` of its motion to the other frame: the reference at the LQ instant, ``(H_lq, W_lq)`` metres."""
    return warper.warp(depth_o, motion=np.float32(frac) * motion)


class FlowMotion:
    """Pairs' references moved to the LQ instant by scene flow (the thin class around :class:`SceneFlow`
    and :func:`moved_reference`), for :class:`align.motion.MotionReference` (its ``moved``).

    Args:
        read_depth: ``read_depth(i)`` -> HQ depth frame ``i``, ``(H, W)`` float32 metres.
        read_color: ``read_color(i)`` -> HQ colour frame of depth frame ``i``, RGB uint8, or ``None``
            when it has none (the pair then falls back to :mod:`align.motion`'s edges).
        warper: :class:`align.warp.DepthWarper` from the HQ depth camera to the LQ image.
        scene_flow: :class:`SceneFlow` of the HQ rig.
    """

    def __init__(self, read_depth, read_color, warper, scene_flow: SceneFlow, *, keep: int = 4) -> None:
        self._read_depth, self._read_color, self.warper, self.scene_flow = read_depth, read_color, warper, scene_flow
        self._flow = ColorFlow()
        self._keep = max(int(keep), 2)
        self._depth: dict[int, np.ndarray] = {}
        self._grey: dict[int, np.ndarray | None] = {}

    def _cached(self, cache: dict, i: int, make):
        if i not in cache:
            if len(cache) >= self._keep:
                cache.pop(next(iter(cache)))
            cache[i] = make(i)
        return cache[i]

    def __call__(self, own: int, other: int, frac: float) -> np.ndarray | None:
        """The reference of HQ frame ``own`` at ``frac`` of the way to frame ``other`` (LQ image,
        metres, NaN = none), or ``None`` when either frame has no colour image."""
        def grey(i):
            c = self._read_color(i)
            return None if c is None else flow_image(c, scale=float(self.scene_flow.flow_scale))

        go, gx = (self._cached(self._grey, k, grey) for k in (own, other))
        if go is None or gx is None:
            return None
        do, dx = (self._cached(self._depth, k, self._read_depth) for k in (own, other))
        motion, _ = self.scene_flow.motion(do, dx, self._flow(go, gx))
        return moved_reference(self.warper, do, motion, frac)
