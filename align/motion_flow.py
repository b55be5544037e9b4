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
2. the dense optical flow from ``o``'s colour image to ``x``'s (OpenCV's DIS, ultrafast preset down to pyramid
   level ``FLOW_FINEST``, the image itself, with patches ``FLOW_PATCH_STRIDE`` apart, on grey images reduced to
   ``flow_scale``) carries it to its colour position in ``x``; the same
   displacement, scaled by the focal-length ratio, gives its depth pixel ``q`` in ``x`` (the
   colour-to-depth parallax changes with the point's depth change only, millimetres);
3. ``P_x`` is ``x``'s sample at ``q``, unprojected. It is trusted when its depth is within
   ``max_jump_m`` of the point's (a flow that lands on another surface is not the point's motion);
   untrusted samples take the mean motion of the trusted ones **of their own surface** (depth within
   ``max_jump_m``) within ``fill_px`` (else none): a silhouette's samples whose flow carried them off
   their body take their body's motion, not the background's standing still.

**The flow's gain.** DIS at its ultrafast preset finds only part of a walking person's image motion:
against the simulator's true motion (session 8, seeds 1-3, moving HQ samples) the flow along the true
direction is 0.52 of the true shift for shifts of 1-3 px, 0.71 for 3-6, 0.77 for 6-10 and 0.82 for 10-20
(endpoint error 2.1 px mean): patches of its coarse finest level straddle the silhouettes and the still
background pulls them down. With the flow the simulator's geometry gives (the true optical flow), session
7's version of this module lands within 0.5-0.7 mm of synchronous frames (seeds 2 and 5: 2.67, 2.88 mm):
what is left is the optical flow. So
before step 3 the flow is multiplied by the factor of ``gains`` that carries the most moving samples
(flow over ``GAIN_MIN_PX``) onto their own surface in ``x`` (count landing minus count not): too small
a gain leaves a body's trailing samples on the background it uncovered, too large a one throws its
leading samples onto the background ahead. One factor per pair: the bias is a property of the flow,
not of each point. A finer DIS for every pair (finest scale 1, patch stride 6: endpoint error 1.5 px, 2.5x the
cost) did not lower the reference's error (3.39 4.14 3.03 mm on seeds 1-3).

**A finer flow where the fast one fails.** On a near person moving 10-20 px per frame DIS ultrafast can
find a third of the motion or less (seed 5's HQ frame 8: endpoint error 8.3 px of 12.6; no gain puts it
back). Such a pair shows itself: its moving samples land on their own surface less often (0.60-0.73 of
them at the best gain, against 0.77-0.87 elsewhere). Below ``FALLBACK_LANDED`` the pair's flow is found
again at DIS's medium preset without its variational refinement (14 ms instead of 2.2 ms; session 8: 3 of 30
pairs on seeds 1-3; session 13, behind the level-0 flow: 3 of 180 pairs of seeds 1-18, 5.0 ms against the
primary flow's 2.0 ms), decided right after the gain vote (the failed flow's step 3, fill and expansion are not
computed).

**Thin fast limbs** (session 13). DIS's coarsest patches straddle an arm a few flow pixels wide, and the
still background pulls them down; down to level 1 (1/8 of the colour image, sessions 9-12) nothing finer
puts the arm's motion back. An arm swinging 20-25 LQ pixels per frame (seed 12's pair 4: moved 5 px in the
7 ms, carried 1-3.5 px; 82 % of the samples on the worst pixels untrusted, i.e. filled with the slower upper
arm's motion) then leaves a sliver behind it where the reference keeps the arm and the truth sees the
background: 291 px (0.8 % of the ROI) carried 90 % of that pair's error (18.9 mm MAE). The same slivers
lie where the plain warp errs too (it moves nothing), which hid that the flow moved the arm too little. A bar 12 px
wide moving 5 px per frame gets 0.44 of its motion at level 1, 0.98 at level 0 (the tests). Since session 12
made the simulated ToF HQ integrate its footprint these slivers are no longer hidden by the eroded
silhouettes of the point-sampled HQ, and they put seeds 9, 12 and 16 over 2 mm from synchronous frames.

A trusted sample whose flow is under ``STILL_PX`` and whose depth changes by under ``STILL_DZ_M``
stands still: motion 0 (moved by ``frac`` of under half a pixel the warp does not change; its depth
change would be the two frames' noise), and blocks whose samples all stand still skip the expansion.

:func:`moved_reference` then warps ``o`` with the points moved by ``frac (P_x - P)``
(:meth:`align.warp.DepthWarper.warp`'s ``motion``): silhouettes land where they are at the LQ
instant, limbs included that moved more than their own width (which choosing per pixel between the
two frames, :mod:`align.motion`, cannot recover). Disocclusions the own frame did not see stay holes.

Steps 1-2, the gain, step 3 and the fill are compiled passes (:mod:`align._flow_kernel`). With ``stride``
> 1 (2, the default) the flow is found for every ``stride``-th sample only; every sample then takes the
bilinear mean of the motions of the block samples around it that lie on its own surface (depth within
``max_jump_m``), so a block across a silhouette does not hand one side the other's motion, and keeps its
own depth change along their flow. The motion is written rotated into the LQ camera over the warper's
source crop (:class:`align.warp.CropMotion`), as the warp adds it. The scene-flow reference needs no plain
warp of the pair's frame (:class:`align.motion.MotionReference`).

Where it stands (session 13; clean people sessions 7 ms out of phase, 2 s, scale 1, 10 pairs per session, MAE
against the truth over the ROI, session 10's scorer on ``strict`` edges and align's own references under the
default ``footprint-fg``): every one of seeds 1-36 lands within 2 mm of the same seed's synchronous frames, under
both (strict: gaps 0.10-1.40 mm on seeds 1-18 where the setting was chosen, 0.27-1.31 on seeds 25-36 simulated
after it; footprint-fg: 0.13-1.80 and 0.28-1.94); the plain warp reads 15-46 mm, synchronous frames 1.9-2.5 mm.
The flow masks nothing: net ROI reference pixels lost against the plain warp -0.1-1.5 %. CPU throughput 0.53 of
the plain warp (0.59 with session 12's coarser flow, the same run; seed 1, 30 consecutive pairs). Every setting
was chosen on a few seeds and checked on held-out ones; the measurements, the settings tried and dropped, and the
per-pair costs: ``docs/motion_flow.md``.
"""
from __future__ import annotations

import cv2
import numpy as np

from align.errors import WarpInputError
from align.warp import CropMotion

#: grey images for the flow are the HQ colour images reduced by this factor
DEFAULT_FLOW_SCALE = 0.25
#: DIS's finest pyramid level on them (:class:`ColorFlow`'s ``finest``): 0, the quarter-size image itself (session
#: 13; sessions 9-12 stopped at level 1, 1/8 of the colour image, where an arm a few flow pixels wide that moves half
#: its width per frame gets a third to two thirds of its motion: the module docstring's "Thin fast limbs")
FLOW_FINEST = 0
#: ... with DIS's patches this many pixels apart (ultrafast's own 4 costs 2.9 ms a pair at level 0, 5 costs 2.0;
#: 6 loses the arms again: session 13)
FLOW_PATCH_STRIDE = 5
#: a flow target whose depth differs from the point's by more than this is another surface (m)
DEFAULT_MAX_JUMP_M = 0.08
#: untrusted samples take the mean motion of trusted ones of their own surface within this many depth pixels
DEFAULT_FILL_PX = 16
#: factors tried on the optical flow (:class:`SceneFlow`'s ``gains``): DIS at its ultrafast preset finds
#: 0.5-0.8 of the true image motion of moving people (measured against the simulator's, session 8); of session 9's
#: six (1.0-1.7) these three were chosen on 147 of the 169 pairs that kept the fast flow; alone they land no
#: worse (session 10). With the flow at level 0 (session 13) the vote takes 1.1 on 171 of 180 pairs (seeds 1-18);
#: adding 1.0 is worse, +0.08 mm [+0.04, +0.13] pooled over seeds 1-18
DEFAULT_GAINS = (1.1, 1.2, 1.35)
#: a pair whose moving samples land on their own surface less often than this share (at the best gain) gets
#: the flow again at DIS's ``FALLBACK_PRESET``
FALLBACK_LANDED = 0.75
FALLBACK_PRESET = cv2.DISOPTICAL_FLOW_PRESET_MEDIUM
#: ... at its own finest level (1 on the half-size image: 0 on the quarter-size one), without its variational
#: refinement (14 instead of 22 ms; as accurate on seeds 1-3, 5 and 9, session 9)
FALLBACK_FINEST = 0
FALLBACK_REFINEMENT = 0
#: :func:`settle_flow`: the flow is 0 where the grey images changed by under this many grey levels (5x5
#: mean) on texture over this (5x5 mean of the absolute Sobel gradients)
SETTLE_CHANGE = 3
SETTLE_TEXTURE = 40
#: samples whose flow is at most this many depth pixels do not vote on the gain
GAIN_MIN_PX = 0.5
#: a trusted sample whose flow (times the gain) is at most this many depth pixels, and whose depth changes by
#: at most ``STILL_DZ_M``, stands still: motion 0 (moved by under half a pixel, its depth change the noise)
STILL_PX = 0.5
STILL_DZ_M = 0.02
#: the motion is found for every this-many-th sample along each axis; its block of samples shares it
DEFAULT_STRIDE = 2


def flow_image(color: np.ndarray, *, scale: float = DEFAULT_FLOW_SCALE) -> np.ndarray:
    """The grey image the flow runs on: ``color`` ``(H, W, 3)`` RGB uint8 (or ``(H, W)`` grey) reduced
    by ``scale``, uint8."""
    g = color if color.ndim == 2 else cv2.cvtColor(np.ascontiguousarray(color), cv2.COLOR_RGB2GRAY)
    while scale <= 0.5 and g.shape[0] % 2 == 0 and g.shape[1] % 2 == 0 and (1 / scale).is_integer():
        # halvings: OpenCV's fast 2x2 mean (a 4x4 mean in one call costs 0.3 ms more on 960x540)
        g, scale = cv2.resize(g, (g.shape[1] // 2, g.shape[0] // 2), interpolation=cv2.INTER_AREA), scale * 2
    if scale == 1:
        return np.ascontiguousarray(g, np.uint8)
    return cv2.resize(g, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)


def settle_flow(flow: np.ndarray, grey_o: np.ndarray, grey_x: np.ndarray, *, max_change: float | None = None,
                min_texture: float | None = None) -> np.ndarray:
    """``flow`` ``(h, w, 2)`` float32 with 0 where the image did not change: the 5x5 mean absolute difference of
    the grey images ``grey_o`` and ``grey_x`` ``(h, w)`` uint8 under ``max_change`` grey levels on texture (the
    5x5 mean of ``grey_o``'s absolute Sobel gradients over ``min_texture``; inside a uniform surface a move
    changes nothing). DIS spreads a moving body's flow over the still background around it (half of the
    still samples of people sessions move by over 0.5 px); this puts ~70 % of those back at rest while
    stopping 0.2 % of the moving pixels (session 8, seed 1, against the simulator's true flow).
    ``None``: ``SETTLE_CHANGE``, ``SETTLE_TEXTURE``. A new array."""
    change = cv2.blur(cv2.absdiff(grey_o, grey_x), (5, 5))
    texture = cv2.blur(cv2.add(cv2.convertScaleAbs(cv2.Sobel(grey_o, cv2.CV_16S, 1, 0), alpha=0.25),
                               cv2.convertScaleAbs(cv2.Sobel(grey_o, cv2.CV_16S, 0, 1), alpha=0.25)), (5, 5))
    moved = cv2.threshold(change, (SETTLE_CHANGE if max_change is None else max_change) - 0.5, 255, cv2.THRESH_BINARY)[1]
    flat = cv2.threshold(texture, (SETTLE_TEXTURE if min_texture is None else min_texture) / 4, 255,
                         cv2.THRESH_BINARY_INV)[1]
    keep = cv2.bitwise_or(moved, flat)  # (OpenCV: a masked operation zeroes the rest; numpy's where costs 5x)
    flow = np.ascontiguousarray(flow, np.float32)
    return cv2.bitwise_and(flow, flow, mask=keep)


class ColorFlow:
    """Dense optical flow between two grey images (OpenCV DIS at ``preset`` with its finest pyramid level ``finest``,
    its patches ``patch_stride`` pixels apart and ``refinement`` variational refinement iterations, ``None``: the
    preset's; one per thread). ``preset`` ``None``: the module's flow, ultrafast at ``FLOW_FINEST`` with patches
    ``FLOW_PATCH_STRIDE`` apart."""

    def __init__(self, preset: int | None = None, *, finest: int | None = None, refinement: int | None = None,
                 patch_stride: int | None = None) -> None:
        import threading

        self._local = threading.local()
        self.preset = cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST if preset is None else int(preset)
        finest = FLOW_FINEST if finest is None and preset is None else finest
        patch_stride = FLOW_PATCH_STRIDE if patch_stride is None and preset is None else patch_stride
        self.finest = None if finest is None else int(finest)
        self.patch_stride = None if patch_stride is None else int(patch_stride)
        if self.patch_stride is not None and self.patch_stride < 1:
            raise WarpInputError(f"optical flow patch stride must be a positive number of pixels, got {patch_stride!r}")
        self.refinement = None if refinement is None else int(refinement)

    def __call__(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Flow ``(h, w, 2)`` float32 pixels of ``a``'s pixels into ``b``."""
        dis = getattr(self._local, "dis", None)
        if dis is None:
            dis = self._local.dis = cv2.DISOpticalFlow_create(self.preset)
            if self.finest is not None:
                dis.setFinestScale(self.finest)
            if self.patch_stride is not None:
                dis.setPatchStride(self.patch_stride)
            if self.refinement is not None:
                dis.setVariationalRefinementIterations(self.refinement)
        if a.shape != b.shape:
            raise WarpInputError(f"flow images differ in size: {a.shape} and {b.shape}")
        return dis.calc(a, b, None)


class SceneFlow:
    """Each sample's motion from an HQ frame ``o`` to another frame ``x`` (the module docstring's
    steps 1-3) for one HQ rig; the rays and the colour projection are set up once.

    Args:
        K_depth, K_color, T_color_depth: the HQ depth and colour cameras (colour from depth, metres).
        flow_scale, max_jump_m, fill_px, stride: the module constants' meaning; ``None``: their defaults.
        gains: factors tried on the optical flow, the one kept carrying most moving samples onto their own
            surface in the other frame (:attr:`last_gain`); ``None``: ``DEFAULT_GAINS``; ``(1.0,)``: the flow as it is.
    """

    def __init__(self, K_depth, K_color, T_color_depth, *, flow_scale: float | None = None,
                 max_jump_m: float | None = None, fill_px: int | None = None, stride: int | None = None,
                 gains=None) -> None:
        f32 = np.float32
        self.K_depth, self.K_color, self.T = K_depth, K_color, T_color_depth
        self.flow_scale = f32(DEFAULT_FLOW_SCALE if flow_scale is None else flow_scale)
        self.max_jump_m = f32(DEFAULT_MAX_JUMP_M if max_jump_m is None else max_jump_m)
        self.fill_px = int(DEFAULT_FILL_PX if fill_px is None else fill_px)
        self.stride = int(DEFAULT_STRIDE if stride is None else stride)
        if self.stride < 1:
            raise WarpInputError(f"scene flow stride must be a positive number of samples, got {stride!r}")
        self.gains = np.asarray(DEFAULT_GAINS if gains is None else gains, f32).ravel()
        if self.gains.size == 0 or not (self.gains > 0).all():
            raise WarpInputError(f"scene flow gains must be positive factors, got {gains!r}")
        self.last_gain, self.last_landed, self.last_refined = 1.0, (0, 0), False
        rays = _rays(K_depth)  # (H, W, 3) float32, z = 1, undistorted
        self._rays = np.ascontiguousarray(rays[..., :2])  # (H, W, 2)
        self._Rr = _rotated(T_color_depth.R, rays, pinhole=not K_depth.has_distortion)  # (3, H, W)
        self._t = T_color_depth.t.astype(f32)
        self._cams = None  # steps 1-2's camera tuple (pinhole colour camera: the same every pair)

    def motion(self, depth_o: np.ndarray, depth_x: np.ndarray, flow, *,
               scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """``(motion, trusted)`` of frame ``o``'s samples towards frame ``x``.

        Args:
            depth_o, depth_x: HQ depth frames ``(H, W)`` float32 metres (NaN = none).
            flow: :class:`ColorFlow`'s flow ``(h, w, 2)`` float32 of ``o``'s grey colour image into ``x``'s
                (:func:`flow_image`).
            scale: the motion returned is this fraction of the motion to ``x`` (the LQ instant's share).
        Returns:
            ``motion`` ``(H, W, 3)`` float32 metres in ``o``'s depth camera frame (0 where neither the
            sample nor a trusted neighbour within ``fill_px`` has one) and ``trusted`` ``(H, W)`` bool.
        """
        d, dx = self._depths(depth_o, depth_x)
        out, trusted = self._planar(d, dx, flow, scale, np.eye(3, dtype=np.float32), (0, d.shape[0], 0, d.shape[1]), 3)
        st = self.stride
        trusted = np.repeat(np.repeat(trusted, st, axis=0), st, axis=1)[:d.shape[0], :d.shape[1]] if st > 1 else trusted
        return np.ascontiguousarray(np.moveaxis(out, 0, -1)), trusted

    def crop_motion(self, depth_o: np.ndarray, depth_x: np.ndarray, flow, *, scale: float, warper,
                    refine=None) -> CropMotion:
        """:meth:`motion` laid out for ``warper`` (:class:`align.warp.DepthWarper` from the HQ depth camera):
        rotated into its destination camera, over its source crop (:class:`align.warp.CropMotion`), as the
        compiled pass writes it: no ``(H, W, 3)`` image of motions, no rotation of one, no copy.

        ``refine``: ``None`` or ``(min_landed, finer)``: when under ``min_landed`` (a share) of the moving samples
        land on their own surface at the best gain (:attr:`last_landed`), ``finer()`` gives the flow again (a
        finer optical flow) and steps 1-3 run on it instead (:attr:`last_refined`); decided after the gain,
        so the failed flow's step 3, fill and expansion are never computed."""
        d, dx = self._depths(depth_o, depth_x)
        out, _ = self._planar(d, dx, flow, scale, warper.T.R.astype(np.float32), tuple(int(c) for c in warper.crop), 4,
                              refine)
        return CropMotion(dst=out[:3].reshape(3, -1), dz=out[3].reshape(-1))

    def _depths(self, depth_o: np.ndarray, depth_x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = np.ascontiguousarray(depth_o, np.float32)
        if d.shape != self._rays.shape[:2] or np.shape(depth_x) != d.shape:
            raise WarpInputError(f"depth frames are {d.shape} and {np.shape(depth_x)}, the HQ depth camera "
                                 f"{self._rays.shape[:2]}")
        return d, np.ascontiguousarray(depth_x, np.float32)

    def _shifts(self, d: np.ndarray, dx: np.ndarray, flow, crop: tuple):
        """Steps 1-2 and the flow's gain (:attr:`last_gain`, :attr:`last_landed`) over ``crop``:
        ``(cams, grid, low shape, shift (Hs, Ws, 2) times the gain, has (Hs, Ws))`` (:mod:`align._flow_kernel`)."""
        from align._flow_kernel import flow_gain, scene_shift

        f32 = np.float32
        cams = self._cams
        if cams is None or cams[6].size:
            Kd, Kc, s = self.K_depth, self.K_color, self.flow_scale
            uv = np.stack(self._colour_position(d)) if Kc.has_distortion else np.zeros((2, 0, 0), f32)
            cams = self._cams = (
                self._rays, self._Rr, self._t, np.array([Kc.fx, Kc.fy, Kc.cx, Kc.cy, s], f32),
                np.array([Kd.fx / Kc.fx / s, Kd.fy / Kc.fy / s], f32),
                np.zeros(0, f32) if Kd.has_distortion else np.array([Kd.fx, Kd.fy, Kd.cx, Kd.cy], f32), uv.astype(f32))
        st, (r0, r1, c0, c1) = self.stride, crop
        g0, h0 = r0 - r0 % st, c0 - c0 % st  # blocks on the image's grid, whatever the crop
        grid = (np.int64(g0), np.int64(h0), np.int64(st))
        low = (-(-(r1 - g0) // st), -(-(c1 - h0) // st))
        shift, has = np.empty((*low, 2), f32), np.empty(low, bool)
        scene_shift(d, np.ascontiguousarray(flow, f32), cams, grid, shift, has)
        k, landed, moving = flow_gain(d, dx, shift, has, grid, self.gains, self.max_jump_m, f32(GAIN_MIN_PX))
        self.last_gain, self.last_landed = round(float(self.gains[k]), 6), (int(landed), int(moving))
        if self.last_gain != 1:
            shift *= self.gains[k]
        return cams, grid, low, shift, has

    def _planar(self, d: np.ndarray, dx: np.ndarray, flow, scale: float, R: np.ndarray, crop: tuple, channels: int,
                refine=None):
        """Steps 1-3, the flow's gain, the fill and (``stride`` > 1) the blocks' expansion over the rows
        ``crop[0]:crop[1]`` and columns ``crop[2]:crop[3]``: ``(out (channels, Hc, Wc), trusted (Hs, Ws))``
        (:mod:`align._flow_kernel`). ``refine``: :meth:`crop_motion`'s."""
        from align._flow_kernel import block_depths, expand_blocks, fill_offsets, fill_untrusted, scene_motion

        f32 = np.float32
        cams, grid, low, shift, has = self._shifts(d, dx, flow, crop)
        self.last_refined = False
        if refine is not None:
            landed, moving = self.last_landed
            if moving and landed < refine[0] * moving:  # decided before step 3: the fast flow's rest is not computed
                cams, grid, low, shift, has = self._shifts(d, dx, refine[1](), crop)
                self.last_refined = True
        st, (r0, r1, c0, c1) = self.stride, crop
        out = np.empty((channels, *low), f32)
        trusted, still = np.empty(low, bool), np.empty(low, bool)
        scene_motion(d, dx, shift, has, cams, np.ascontiguousarray(R, f32), grid, f32(scale), self.max_jump_m,
                     f32(STILL_PX), f32(STILL_DZ_M), out, trusted, still)
        dl = block_depths(d, grid, low)
        if self.fill_px > 0:  # only samples with depth (a block sample without one lends its block nothing)
            fill_untrusted(out, trusted, fill_offsets(np.int64(-(-self.fill_px // st))), dl, self.max_jump_m)
        if st == 1:
            return out, trusted
        full = np.empty((channels, r1 - r0, c1 - c0), f32)
        expand_blocks(out, trusted, still, shift, dl, d, dx, np.ascontiguousarray(R, f32), grid, (np.int64(r0), np.int64(c0)),
                      f32(scale), self.max_jump_m, full)
        return full, trusted

    def _colour_position(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each sample's position on the reduced flow image (x, y), NaN where it has no depth (a colour
        camera with lens distortion; the pinhole case is computed in :func:`align._flow_kernel.scene_motion`)."""
        s = self.flow_scale
        with np.errstate(invalid="ignore"):
            P = d[..., None] * np.moveaxis(self._Rr, 0, -1) + self._t
        uv = self.K_color.project(P.reshape(-1, 3)).reshape(*d.shape, 2).astype(np.float32)
        return (uv[..., 0] + np.float32(0.5)) * s - np.float32(0.5), (uv[..., 1] + np.float32(0.5)) * s - np.float32(0.5)


def _rays(K) -> np.ndarray:
    """``K.ray_grid()`` as float32; a pinhole camera's from its two axes (the same float64 arithmetic, without
    the ``(H W, 2)`` pixel grid: 9 ms -> under 1 ms at 512x424, once per :class:`SceneFlow`)."""
    if K.has_distortion:
        return K.ray_grid().astype(np.float32)
    H, W = K.shape
    rays = np.ones((H, W, 3), np.float32)
    rays[..., 0] = ((np.arange(W, dtype=np.float64) - K.cx) / K.fx)[None, :]
    rays[..., 1] = ((np.arange(H, dtype=np.float64) - K.cy) / K.fy)[:, None]
    return rays


def _rotated(R: np.ndarray, rays: np.ndarray, *, pinhole: bool) -> np.ndarray:
    """``R @ ray`` for every ray of ``rays`` ``(H, W, 3)`` float32, ``(3, H, W)`` float32, summed in float64. A
    pinhole camera's rays vary along one axis each: three broadcast sums instead of a product over the grid."""
    if not pinhole:
        return np.ascontiguousarray(np.einsum("ij,hwj->ihw", R, rays), np.float32)
    x, y = rays[0, :, 0].astype(np.float64)[None, :], rays[:, 0, 1].astype(np.float64)[:, None]
    out = np.empty((3, *rays.shape[:2]), np.float32)
    for k in range(3):
        out[k] = R[k, 0] * x + R[k, 1] * y + R[k, 2]
    return out


def moved_reference(warper, depth_o: np.ndarray, motion, frac: float) -> np.ndarray:
    """Frame ``o`` warped by ``warper`` (:class:`align.warp.DepthWarper`) with every point moved by
    ``frac`` of its motion to the other frame: the reference at the LQ instant, ``(H_lq, W_lq)`` metres.
    ``motion``: ``(H, W, 3)`` (source frame) or a :class:`align.warp.CropMotion` (already ``frac`` of the way)."""
    if isinstance(motion, CropMotion) or frac == 1:
        return warper.warp(depth_o, motion=motion)
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
        warp: ``warp(depth, motion)`` -> the HQ frame warped by ``warper`` with its points moved
            (:class:`align.warp.CropMotion`), ``(H_lq, W_lq)`` metres; ``None``: ``warper.warp`` (an edge
            rule that warps its own way passes its warp, :meth:`align.reference_edges.EdgeRule.warp`).
    """

    def __init__(self, read_depth, read_color, warper, scene_flow: SceneFlow, *, keep: int = 4,
                 warp=None) -> None:
        self._read_depth, self._read_color, self.warper, self.scene_flow = read_depth, read_color, warper, scene_flow
        self._warp = warp
        self._flow = ColorFlow()
        self._fallback = ColorFlow(FALLBACK_PRESET, finest=FALLBACK_FINEST, refinement=FALLBACK_REFINEMENT)
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
        flow = settle_flow(self._flow(go, gx), go, gx)
        finer = (FALLBACK_LANDED, lambda: settle_flow(self._fallback(go, gx), go, gx))  # where the fast flow failed
        # already frac of the way
        motion = self.scene_flow.crop_motion(do, dx, flow, scale=frac, warper=self.warper, refine=finer)
        if self._warp is not None:
            return self._warp(do, motion)
        return moved_reference(self.warper, do, motion, 1.0)
