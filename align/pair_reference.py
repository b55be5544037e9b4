"""The reference of a frame pair as ``align`` builds it: the one way to warp (issue 12).

An HQ depth frame becomes the LQ frame's reference in three steps, always in this order:

1. the warp onto the LQ image (:class:`align.warp.DepthWarper`), with the edge rule's reach past a
   surface's last sample (:mod:`align.reference_edges`: 0 for the ``strict`` rule, the default;
   the ``mixed`` rule warps without the HQ's mixed samples and masks what they hide,
   :meth:`align.reference_edges.EdgeRule.warp`);
2. when the LQ frame is exposed apart from its HQ frame, the reference carried to the LQ instant
   from the two HQ frames around it (:mod:`align.motion`, or by scene flow along the HQ colour
   images' optical flow, :mod:`align.motion_flow`);
3. the edge rule's mask (far side of reference edges) on the result; the ``-fg`` rules mask there only
   what the ROI would score, given the ROI's background model.

The aligned dataset's references (:func:`align.pipeline.write_pair_dataset`) and every error
reported against truth for them (the loop's end-to-end table, :mod:`align.loop.report`) come from
:class:`PairReferences`, so the numbers a report prints are those of the references it writes (for the
``-fg`` rules the loop's table has no ROI background and scores the base rule's references; the written
ones differ from them only where the reference lies on the background, outside the ROI).
No I/O: HQ frames come through a callable.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from align.errors import OptionError
from align.motion import MotionReference, PairMotion
from align.motion_flow import FlowMotion, SceneFlow
from align.reference_edges import EdgeRule
from align.warp import DepthWarper

#: how a pair's reference is carried to the LQ instant (:class:`ReferenceOptions`)
MOTION_MODELS = ("edges", "flow")


@dataclass(frozen=True)
class ReferenceOptions:
    """How references are built: ``reference_edges`` (edge rule by name, :mod:`align.reference_edges`),
    ``edge_rel`` (relative depth step of an edge, for the warp and the rule), ``motion`` (carry to the
    LQ instant), ``motion_min_dt_ms`` (pairs closer in time keep the plain warp), ``motion_model``
    (``"flow"``, the default since session 13: the HQ frame's points moved along the HQ colour images' optical
    flow, :mod:`align.motion_flow`, where the HQ frames have colour; ``"edges"``: :mod:`align.motion`)."""

    reference_edges: str = "footprint-fg"
    edge_rel: float = 0.03
    motion: bool = True
    motion_min_dt_ms: float = 1.0
    motion_model: str = "flow"

    @classmethod
    def from_meta(cls, meta: dict) -> "ReferenceOptions":
        """The options an aligned dataset was written with, from its ``aligned.json`` (defaults where absent)."""
        edges, motion = meta.get("reference_edges") or {}, meta.get("motion") or {}
        d = cls()
        return cls(reference_edges=edges.get("rule", d.reference_edges), edge_rel=float(edges.get("edge_rel", d.edge_rel)),
                   motion=bool(motion.get("enabled", d.motion)),
                   motion_min_dt_ms=float(motion.get("min_dt_ms", d.motion_min_dt_ms)),
                   # written before the scene flow existed (session 8): the edges model, the only one then
                   motion_model=str(motion.get("motion_model", "edges" if motion else d.motion_model)))


@dataclass
class PairReference:
    """One pair's reference: ``depth`` ``(H, W)`` float32 metres on the LQ image (NaN = none), how the
    motion step made it (``motion``), and ``edge_mask`` ``(H, W)`` bool, the pixels the edge rule masked."""

    depth: np.ndarray
    motion: PairMotion
    edge_mask: np.ndarray


class PairReferences:
    """References of the pairs of one session (the module docstring's three steps).

    Args:
        read_hq: ``read_hq(i)`` -> HQ depth frame ``i``, ``(h, w)`` float32 metres, NaN = none.
        K_hq, K_lq, T_lq_hq: the geometry (:class:`align.warp.DepthWarper`'s).
        t_hq_us: ``(N,)`` HQ frame stamps, µs (the motion step's brackets).
        options: :class:`ReferenceOptions`; ``None``: ``align``'s defaults.
        hq_color: for ``motion_model="flow"``: ``(read_color, K_hq_color, T_hqcolor_hqdepth)``,
            ``read_color(i)`` -> HQ colour image of depth frame ``i`` (RGB uint8) or ``None``; without
            it the edges carry every pair.
        background: the ROI's background model ``(H, W)`` float32 metres on the LQ image
            (:func:`align.roi.background_depth`), for the rules that mask only what the ROI scores
            (``-fg``, :attr:`align.reference_edges.EdgeRule.scored_only`); ``None``: they mask as the others.
    """

    def __init__(self, read_hq: Callable[[int], np.ndarray], *, K_hq, K_lq, T_lq_hq, t_hq_us: np.ndarray,
                 options: ReferenceOptions | None = None, hq_color: tuple | None = None,
                 background: np.ndarray | None = None) -> None:
        self.options = options or ReferenceOptions()
        self.background = background
        if self.options.motion_model not in MOTION_MODELS:
            raise OptionError(f"motion model must be one of {', '.join(MOTION_MODELS)}, got {self.options.motion_model!r}",
                              option="motion_model")
        self.rule = EdgeRule.named(self.options.reference_edges, edge_rel=self.options.edge_rel)
        self._warper = DepthWarper(K_hq, K_lq, T_lq_hq, edge_rel=self.options.edge_rel, edge_reach=self.rule.edge_reach)
        self._read_hq = read_hq
        self._frame_masks: dict[int, np.ndarray] = {}  # what the rule masked at the warp, per HQ frame
        moved = None
        if self.options.motion_model == "flow" and hq_color is not None:
            read_color, K_color, T_color_depth = hq_color
            moved = FlowMotion(read_hq, read_color, self._warper, SceneFlow(K_hq, K_color, T_color_depth),
                               warp=self._warp_moved)
        self._moved_mask: np.ndarray | None = None  # what the rule masked at the moved warp, this pair
        self.motion = MotionReference(self._warp, t_hq_us, enabled=self.options.motion,
                                      min_dt_us=1000 * self.options.motion_min_dt_ms, moved=moved)

    def _warp(self, i: int) -> np.ndarray:
        depth, mask = self.rule.warp(self._warper, self._read_hq(i), background=self.background)
        if mask is not None:
            if len(self._frame_masks) >= 4:
                self._frame_masks.pop(next(iter(self._frame_masks)))
            self._frame_masks[i] = mask
        return depth

    def _warp_moved(self, depth: np.ndarray, motion) -> np.ndarray:
        """An HQ frame warped with its points moved by scene flow, as the rule warps (its mask kept)."""
        out, self._moved_mask = self.rule.warp(self._warper, depth, motion=motion, background=self.background)
        return out

    def __call__(self, i: int, dt_us: float) -> PairReference:
        """The reference of HQ frame ``i`` for the LQ frame exposed ``dt_us`` after it (µs, on the HQ clock:
        ``t_lq - (t_hq + shift)``)."""
        self._moved_mask = None
        ref, pm = self.motion(int(i), float(dt_us))
        depth, mask = self.rule.apply(ref, background=self.background)
        at_warp = self._moved_mask if pm.model == "scene flow" else self._frame_masks.get(int(i))
        if at_warp is not None:  # the rule's mask at the warp, where the pair's reference has no depth
            mask = mask | (at_warp & ~np.isfinite(depth))
        return PairReference(depth=depth, motion=pm, edge_mask=mask)
