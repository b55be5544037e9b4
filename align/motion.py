"""Motion between unsynchronised frames: the reference at the LQ frame's instant, from the two HQ
frames around it (issue 12).

Pure numpy/OpenCV plus one compiled search (:mod:`align._motion_kernel`), no I/O. It reads no LQ
depth and no LQ colour: only the two HQ frames decide, so the reference is not pulled towards the
input that is scored against it.

The problem
-----------
The LQ frame of a pair is exposed ``dt`` after its HQ frame (on the HQ clock, after the time
shift; up to half a frame period either way when the two sensors run out of phase). Whatever
moved in between sits in the warped reference where it was, not where the LQ sensor saw it: on
people walking 7 ms apart that is ~30 mm of MAE against truth, nearly all of it on moving
silhouettes, against ~5 mm when the frames fall together.

The model
---------
The HQ frames ``a`` and ``b`` bracket the LQ instant ``t``: ``t_a <= t <= t_b``, ``alpha = (t -
t_a) / (t_b - t_a)``; the pair's *own* frame is the nearer one. Both are warped to the LQ camera
with the ordinary warp (:class:`align.warp.DepthWarper`, used as it is), giving ``A`` and ``B``
(LQ image, metres, NaN = none). Per LQ pixel ``p``:

1. **One surface in both frames** (both finite, ``|B - A| <= edge_rel * min(A, B)``): over one
   frame period depth is linear in time, ``D = A + alpha (B - A)``.
2. **An occlusion edge crossed p** between the frames (both finite and farther apart; or only the
   own frame has depth, next to such a pixel, where the other frame's hole is the occlusion shadow
   of a moved edge and counts as the far surface): one frame saw the occluder at ``p``, the other
   the surface behind. Edges move at constant velocity over one frame period (first order in time,
   as in 1.), so the instant the edge passed ``p`` follows from where the edge was in each frame.
   With the pixel's midpoint depth ``m = sqrt(A B)`` (the far depth x 1.12 when one is missing),
   label the pixels around it: *near in A* (``A < m``), *near in B*, and *far in both* (``FF``:
   seen in at least one frame, near in neither). Then

   * occluder arriving (near in ``B`` only): its leading edge was ``a = dist(p, near in A)`` behind
     ``p`` at ``t_a`` and ``b = dist(p, FF)`` ahead of ``p`` at ``t_b``;
   * occluder leaving (near in ``A`` only): its trailing edge was ``a = dist(p, FF)`` behind ``p``
     at ``t_a`` and ``b = dist(p, near in B)`` ahead at ``t_b``

   (distances between pixel centres, less half a pixel each: an edge lies between two pixels).
   The other position of the occluder (near in A when arriving, near in B when leaving) is looked
   for along 16 rays; the nearest hit gives the direction the edge moved, and ``FF`` is looked for
   along the opposite ray, so a narrow limb's far side does not pass for its trailing edge. At the
   LQ instant the edge has passed
   ``p`` by ``s = alpha (a + b) - a`` pixels; the pixel shows the other frame's surface when ``s``
   passes ``p`` by more than ``margin_px`` towards it (1 px by default: closer than that the two
   frames' own edge errors, a pixel or so, decide more often wrongly than the own frame), else the
   own frame's. The depth comes from the frame that saw the chosen surface; where that frame has
   none (its occlusion shadow), the pixel has none. A pixel is **masked** (NaN, counted) when an
   edge is not found within ``max_motion_px`` on either side (it moved farther, or there is no
   surface to measure from), and, with ``mask_within_px > 0``, when the edge is within that many
   pixels of ``p`` at the LQ instant (more masking, less error: see the notes of issue 12).
3. **Only one frame has depth, away from a crossed edge**: the own frame's value as it is (NaN
   where the own frame has none). Nothing is invented where the pair's own frame has no depth.

With ``alpha = 0`` or ``1`` every pixel keeps the own frame's value (rule 1 gives it exactly, rule
2 needs ``|s| > margin_px`` towards the other frame); a pair whose frames fall together is not
passed here at all (:class:`MotionReference` keeps the plain warp, bit for bit).

Why edges and not flow: per-point optical flow on depth images was tried first and made the
reference worse (5.3 -> 7.1 mm MAE): it is noisy per point. Distances to whole surfaces are smooth
along an edge by construction. What neither frame saw cannot be recovered this way: a limb that
moved more than its own width passes pixels both frames saw as background, and a surface that
turns shows a depth neither frame had; that error remains (on people walking 7 ms out of phase
it is most of what is left: choosing per pixel whichever of the two frames is right, with the
truth, would leave ~19 mm MAE where the plain warp has ~33 mm; see the notes of issue 12).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from align.errors import OptionError, WarpInputError

#: Relative depth difference between the two frames above which a pixel saw two surfaces.
DEFAULT_MOTION_EDGE_REL = 0.05
#: Farthest an edge is searched for (LQ pixels); a walking person's limbs move ~10-30 px in one
#: 33 ms period at 640x480 and 2-3 m.
DEFAULT_MAX_MOTION_PX = 40.0
#: How far (px) an edge must have passed a pixel before it takes the other frame's surface.
DEFAULT_MARGIN_PX = 1.0
#: Where one frame has no depth, its surface counts as this much farther than the other's.
ONE_SIDED_REL = 0.12
#: Directions the edges are searched along.
RAYS = 16


@dataclass
class Compensated:
    """The reference at the LQ instant.

    ``depth``: ``(H, W)`` float32 metres, NaN = none. ``masked``: ``(H, W)`` bool, pixels where the
    own frame's plain warp has depth and this has none (undecided, or the surface chosen was not
    seen). ``interpolated``: one surface in both frames (rule 1); ``crossed``: an edge crossed the
    pixel and it was decided (rule 2); ``taken_other``: of those, how many took the other frame's
    surface (the pixels the plain warp has wrong).
    """

    depth: np.ndarray
    masked: np.ndarray
    interpolated: int
    crossed: int
    taken_other: int

    @property
    def n_masked(self) -> int:
        return int(self.masked.sum())


def compensate_motion(ref_a: np.ndarray, ref_b: np.ndarray, alpha: float, *, own: str | None = None,
                      edge_rel: float = DEFAULT_MOTION_EDGE_REL, max_motion_px: float = DEFAULT_MAX_MOTION_PX,
                      margin_px: float = DEFAULT_MARGIN_PX, mask_within_px: float = 0.0) -> Compensated:
    """The reference at ``alpha`` of the way from HQ frame ``a`` to ``b`` (see the module docstring).

    Args:
        ref_a, ref_b: the two HQ frames warped to the LQ image, ``(H, W)`` float32 metres, NaN = none.
        alpha: ``(t - t_a) / (t_b - t_a)`` in ``[0, 1]``.
        own: ``"a"`` or ``"b"``, the pair's own HQ frame; ``None``: the nearer in time.
        edge_rel: relative depth difference that separates two surfaces between the frames.
        max_motion_px: farthest an edge is looked for, LQ pixels.
        margin_px: how far an edge must have passed a pixel towards the other frame's state.
        mask_within_px: mask pixels whose edge is closer than this at the LQ instant (0: none).
    """
    A = np.ascontiguousarray(ref_a, np.float32)
    B = np.ascontiguousarray(ref_b, np.float32)
    _check(A, B, alpha=alpha, own=own, edge_rel=edge_rel, max_motion_px=max_motion_px, margin_px=margin_px,
           mask_within_px=mask_within_px)
    alpha = float(alpha)
    own = own or ("a" if alpha <= 0.5 else "b")
    rule_one, rule_two, _ = _kernels()
    out, band = np.empty_like(A), np.empty(A.shape, np.uint8)
    interpolated = rule_one(A, B, np.float32(alpha), np.float32(edge_rel), own == "a", out, band)
    near_band = cv2.dilate(band, np.ones((7, 7), np.uint8))  # one-sided pixels: shadows beside an edge
    masked = np.zeros(A.shape, bool)
    crossed, taken = rule_two(A, B, band, near_band, np.float32(alpha), own == "a", np.float32(1 + ONE_SIDED_REL),
                              np.float32(margin_px), np.float32(mask_within_px), _rays(max_motion_px, A.shape[1]),
                              out, masked)
    return Compensated(depth=out, masked=masked, interpolated=int(interpolated), crossed=int(crossed),
                       taken_other=int(taken))


def _check(A: np.ndarray, B: np.ndarray, **kw) -> None:
    if A.shape != B.shape or A.ndim != 2:
        raise WarpInputError(f"the two warped HQ frames must be images of one shape, got {A.shape} and {B.shape}")
    if not 0.0 <= float(kw["alpha"]) <= 1.0:
        raise OptionError(f"alpha must be within [0, 1], got {kw['alpha']!r}")
    if kw["own"] not in (None, "a", "b"):
        raise OptionError(f"own frame must be 'a' or 'b', got {kw['own']!r}")
    if not kw["edge_rel"] > 0:
        raise OptionError(f"motion edge_rel must be positive, got {kw['edge_rel']!r}")
    if not kw["max_motion_px"] >= 1:
        raise OptionError(f"max_motion_px must be at least 1, got {kw['max_motion_px']!r}")
    if not (kw["margin_px"] >= 0 and kw["mask_within_px"] >= 0):
        raise OptionError(f"margin_px and mask_within_px must be >= 0, got {kw['margin_px']!r}, "
                          f"{kw['mask_within_px']!r}")


_OFFSETS: dict = {}
_KERNEL: list = []


def _offsets(radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``RAYS`` rays of pixel offsets out to ``radius``: ``(dy, dx, dist)``, each ``(RAYS, steps)``,
    ray ``r`` at angle ``2 pi r / RAYS`` (ray ``r + RAYS / 2`` the opposite one)."""
    if radius not in _OFFSETS:
        theta = np.arange(RAYS) * (2 * np.pi / RAYS)
        steps = np.arange(1, int(np.floor(radius)) + 1)
        dy = np.rint(np.outer(np.sin(theta), steps)).astype(np.int64)
        dx = np.rint(np.outer(np.cos(theta), steps)).astype(np.int64)
        _OFFSETS[radius] = (dy, dx, np.hypot(dy, dx).astype(np.float32))
    return _OFFSETS[radius]


def _kernels():
    """``(rule_one, rule_two, step_tables)`` of :mod:`align._motion_kernel` (imported on first use)."""
    if not _KERNEL:
        from align._motion_kernel import rule_one, rule_two, step_tables

        _KERNEL.extend((rule_one, rule_two, step_tables))
    return _KERNEL


def _rays(radius: float, width: int) -> tuple:
    """The search tables for images ``width`` wide (:func:`align._motion_kernel.step_tables`, cached)."""
    key = (radius, int(width))
    if key not in _OFFSETS:
        _OFFSETS[key] = _kernels()[2](*_offsets(radius), np.int64(width))
    return _OFFSETS[key]


def bracket(t_hq_us: np.ndarray, i: int, dt_us: float, *, max_gap: float = 1.6) -> tuple[int, int, float] | None:
    """The HQ frames ``a < b`` around the instant ``t_hq_us[i] + dt_us`` and ``alpha`` from ``a`` to ``b``.

    ``t_hq_us``: ``(N,)`` HQ frame stamps, µs, increasing. ``None`` when the neighbour on that side
    is missing or more than ``max_gap`` median frame periods away (dropped frames in between).
    """
    t = np.asarray(t_hq_us, np.int64)
    if t.size < 2 or dt_us == 0:
        return None
    a, b = (i, i + 1) if dt_us > 0 else (i - 1, i)
    if a < 0 or b >= t.size:
        return None
    span = float(t[b] - t[a])
    if not 0 < span <= max_gap * float(np.median(np.diff(t))):
        return None
    alpha = (float(t[i] - t[a]) + float(dt_us)) / span
    return a, b, min(max(alpha, 0.0), 1.0)


@dataclass(frozen=True)
class PairMotion:
    """How one pair's reference was made: ``dt_us`` (LQ instant minus its HQ frame's, µs), the HQ
    frame indices ``a, b`` and ``alpha`` when compensated (``None`` otherwise), ``masked`` pixels
    (:attr:`Compensated.masked`, and ``masked_map`` the ``(H, W)`` bool image of them), ``valid``
    finite reference pixels, ``reason`` why not compensated, ``model`` how it was (edges or scene flow)."""

    dt_us: float
    frames: tuple[int, int] | None
    alpha: float | None
    masked: int
    valid: int
    reason: str = ""
    masked_map: np.ndarray | None = None
    model: str = "edges"  # how a compensated pair was carried: "edges" (compensate_motion) or "scene flow"


class MotionReference:
    """References at the LQ instants of many pairs (the thin class around :func:`compensate_motion`).

    Args:
        warped: ``warped(i)`` -> HQ depth frame ``i`` warped to the LQ image (the plain warp); called
            at most once per frame while the pairs come in time order (a few are kept: each HQ frame
            serves the pairs on both sides of it).
        t_hq_us: ``(N,)`` HQ frame stamps, µs.
        min_dt_us: pairs closer in time than this keep the plain warp (bit for bit).
        enabled: ``False``: every pair keeps the plain warp.
        edge_rel, max_motion_px: :func:`compensate_motion`'s.
        moved: ``moved(own, other, frac)`` -> the reference of HQ frame ``own`` moved ``frac`` of the
            way to frame ``other`` (:class:`align.motion_flow.FlowMotion`, scene flow), or ``None``
            where it cannot (then the edges decide, as without it); ``None``: edges only.
    """

    def __init__(self, warped, t_hq_us: np.ndarray, *, min_dt_us: float = 1000.0, enabled: bool = True,
                 edge_rel: float = DEFAULT_MOTION_EDGE_REL, max_motion_px: float = DEFAULT_MAX_MOTION_PX,
                 keep: int = 4, moved=None) -> None:
        if not min_dt_us >= 0:
            raise OptionError(f"smallest compensated time apart must be >= 0 us, got {min_dt_us!r}")
        self._warped, self.t_hq_us = warped, np.asarray(t_hq_us, np.int64)
        self.min_dt_us, self.enabled = float(min_dt_us), bool(enabled)
        self.edge_rel, self.max_motion_px = float(edge_rel), float(max_motion_px)
        self._cache: dict[int, np.ndarray] = {}
        self._keep = max(int(keep), 2)
        self._moved = moved

    def warp(self, i: int) -> np.ndarray:
        """The plain warp of HQ frame ``i`` (cached)."""
        i = int(i)
        if i not in self._cache:
            if len(self._cache) >= self._keep:
                self._cache.pop(next(iter(self._cache)))
            self._cache[i] = self._warped(i)
        return self._cache[i]

    def __call__(self, i: int, dt_us: float) -> tuple[np.ndarray, PairMotion]:
        """The reference of the pair (HQ frame ``i``, LQ instant ``dt_us`` after it) and how it was made."""
        br = None
        if self.enabled and abs(dt_us) >= self.min_dt_us:
            br = bracket(self.t_hq_us, int(i), float(dt_us))
        if br is not None and self._moved is not None:  # scene flow: the plain warp is not needed
            a, b, alpha = br
            ref = self._moved(int(i), b if a == i else a, alpha if a == i else 1.0 - alpha)
            if ref is not None:
                return ref, PairMotion(float(dt_us), (a, b), alpha, 0, int(np.isfinite(ref).sum()), model="scene flow")
        own = self.warp(i)
        if br is None:
            why = "off" if not self.enabled else "frames fall together" if abs(dt_us) < self.min_dt_us else "no HQ neighbour"
            return own, PairMotion(float(dt_us), None, None, 0, int(np.isfinite(own).sum()), why)
        a, b, alpha = br
        r = compensate_motion(self.warp(a), self.warp(b), alpha, own="a" if a == i else "b", edge_rel=self.edge_rel,
                              max_motion_px=self.max_motion_px)
        return r.depth, PairMotion(float(dt_us), (a, b), alpha, r.n_masked, int(np.isfinite(r.depth).sum()),
                                   masked_map=r.masked)


def motion_summary(pairs: list, *, enabled: bool, min_dt_ms: float) -> dict:
    """``aligned.json``'s ``motion`` object from ``[(lq_frame, PairMotion, roi_valid, roi_masked)]``
    (``roi_*``: reference pixels with depth / masked inside the region of interest, ``None`` without one).

    Shares are of the pixels the plain warp has depth at (``masked / (valid + masked)``); per pair
    the time apart (ms, LQ instant minus its HQ frame's), ``alpha`` and the masked pixels.
    """
    dt = np.array([abs(pm.dt_us) for _, pm, _, _ in pairs], float) / 1000
    comp = [pm for _, pm, _, _ in pairs if pm.frames is not None]
    masked = sum(pm.masked for pm in comp)
    valid = sum(pm.valid for _, pm, _, _ in pairs)
    roi = [(v, m) for _, _, v, m in pairs if v is not None]
    roi_masked, roi_valid = sum(m for _, m in roi), sum(v for v, _ in roi)
    why: dict[str, int] = {}
    for _, pm, _, _ in pairs:
        if pm.reason:
            why[pm.reason] = why.get(pm.reason, 0) + 1
    return {
        "model": "align.motion: reference at the LQ instant from the two HQ frames around it" if enabled else "off",
        "enabled": bool(enabled), "min_dt_ms": float(min_dt_ms), "pairs": len(pairs), "compensated": len(comp),
        "not_compensated": why,
        "compensated_by": {m: sum(pm.model == m for pm in comp) for m in sorted({pm.model for pm in comp})},
        "time_apart_ms": {"median": float(np.median(dt)) if dt.size else None, "max": float(dt.max()) if dt.size else None},
        "masked_pixels": int(masked), "masked_share": masked / max(valid + masked, 1),
        "roi_masked_share": roi_masked / max(roi_valid + roi_masked, 1) if roi else None,
        "per_pair": [{"lq_frame": int(f), "dt_ms": round(pm.dt_us / 1000, 3),
                      "alpha": None if pm.alpha is None else round(pm.alpha, 4), "masked": int(pm.masked)}
                     for f, pm, _, _ in pairs],
    }
