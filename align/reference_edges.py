"""The warped reference's own error at depth edges, and the edge rule the aligned dataset uses.

Pure numpy/OpenCV, no I/O.

Model
-----
The HQ depth image is coarser than the LQ image it is warped onto (Kinect-class 512x424 at
``fx`` 365 px against 640x480 at ``fx`` 600 px: one HQ step is ~1.6 LQ pixels), and a
time-of-flight sensor mixes the two surfaces in the pixels along every depth edge (flying
pixels; the warp's continuity test drops them, see :mod:`align.warp`). Where a silhouette lies
between two HQ samples the reference cannot know where; whatever the warp guesses there is wrong
by the whole depth jump (0.3-3 m) for some pixels. Few pixels, but they dominate the reference's
RMSE: on a demo-like session (``perf/reference_error.py``) 0.73 % of the ROI is off by more than
50 mm, RMSE 77 mm beside MAE 6.8 mm. Traced, the large errors are of two kinds:

* **reference farther** (73 %): the far surface showing through the near one. The HQ camera sits
  12.5 cm beside the LQ camera, so on one side of every silhouette the LQ camera sees less of the
  background than the HQ camera does: far samples the HQ camera saw up to ~12 HQ pixels from the
  silhouette land, in the LQ image, just inside the near surface's true outline, and win wherever
  the near surface's samples were lost to mixing. They sit on the far side of a reference depth
  edge, within a pixel or two of it.
* **reference nearer** (27 %): on the other side (disocclusion) the near surface, extended half an
  HQ step past its last sample by the warp's midpoint rule, covers background the HQ camera never
  saw next to the near surface.

The rule (:class:`EdgeRule`, ``"strict"``): (1) no surface reaches past its last sample
(``edge_reach=0`` in :class:`align.warp.DepthWarper`), which removes the second kind; (2) the
pixels on the far side of a reference depth edge, within ``mask_px`` (3) of a surface at least
``edge_rel`` nearer, are masked (NaN), which removes most of the first. Every masked pixel is
counted and reported.

The rules (:data:`RULES`, :class:`EdgeRule`):

* ``"midpoint"``: the plain warp: guess, mask nothing.
* ``"strict"``: the rule above.
* ``"mixed"``: also drops the HQ time-of-flight mixes :func:`align.mixed_pixels.mixed_samples` can tell (off
  their surface's line by more than 3 noise deviations, or isolated) and masks what their footprint hides.
* ``"strict-fg"`` / ``"mixed-fg"``: mask as their base rule, but only where the reference is in front of the
  ROI's background model (:func:`align.roi.in_front`): far samples that land inside a silhouette are outside
  the ROI whatever is done with them, and masking them only hands them to the LQ depth, whose stereo edge
  fattening puts them back into the ROI, scored against the truth but not against the reference.
* ``"footprint-fg"`` (the default): ``"strict-fg"`` plus footprint occluders. Every HQ sample near an edge,
  the ones the warp drops included, is splatted over its footprint (:func:`footprint_occluders`, 2.5
  footprints wide), and reference pixels more than 10 % behind it are masked. A nearer surface whose last HQ
  samples the warp cannot link (mixes, a grazing side) otherwise ends short in the reference, and the
  mid-ground samples the HQ camera saw beside it fill the gap inside the LQ silhouette.
* ``"footprint-mixed-fg"``: ``"footprint-fg"`` without warping the mixes ``"mixed"`` drops (they still occlude);
  what they covered is masked and counted.
* ``"footprint-colour-fg"`` (opt-in, session 11): ``"footprint-fg"`` plus the LQ colour image as a witness of the
  silhouette (:func:`colour_edge_mask`): a reference pixel at a silhouette whose LQ colour is at least
  ``COLOUR_EDGE_MARGIN`` closer to a neighbour across the silhouette (a hole or a surface > 10 % farther) than to
  any neighbour on its own surface is masked. Applied only where the LQ colour is co-registered with the LQ depth
  (a colour resampled through the LQ depth would carry the evaluated sensor's own edge errors into the mask).

Where it stands (issue 12 asks for the HQ sensor's RMSE within 2x its MAE against the truth, with no more than
2 % of the ROI masked; the demo, 60 frames, through ``align``). Until session 11 the simulated HQ sampled each
pixel at its centre, and what set the ratio were single pixels at concave corners and slits between limbs thinner
than one HQ step, which vanished between the samples without a trace: no witness (HQ depth, the reference's shape,
LQ or HQ colour, all of them fitted on the truth) found them within the budget, ``"footprint-fg"`` read 2.63
[1.98, 3.34] at 1.79 % masked. A real time-of-flight pixel integrates its footprint and reads a mix there; since
session 12 the simulator renders the footprint (``TofNoise.footprint_samples``, :mod:`capture.sim.noise`), the
mixes flag those pixels, and ``"footprint-fg"`` with a 2 px band (:data:`FOOTPRINT_BAND_PX`; 3 px masks 2.35 %)
reads 1.61 [1.58, 1.65] at 1.03 % masked (seed 1: 1.79; held-out seeds 2, 4-9: 1.67-2.53, four of seven at
most 2, at 0.67-1.08 %). ``"footprint-mixed-fg"`` reads 1.49 at 5.30 %, ``"footprint-colour-fg"`` 1.60 at 1.13 %.
Cost: :func:`footprint_occluders` about 2 ms CPU per demo frame, beside the plain warp's 2.2 ms.

Every measurement behind these choices, session by session, with its commands: ``docs/reference_edges.md``.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from align.errors import OptionError
from align.mixed_pixels import mixed_samples, nearest_around
from align.roi import in_front

#: the footprint rules' far-side band, destination pixels: 2 since session 12 (3 before; with the simulated HQ that
#: integrates its pixel footprints, 3 masks 2.35 % of the demo's ROI, over issue 12's 2 %; ``docs/reference_edges.md``)
FOOTPRINT_BAND_PX = 2
#: the named rules: (edge reach of the warp, mask width in destination pixels, HQ mixed samples as occluders,
#: the band only where the reference is scored, every HQ sample's footprint as an occluder; with both the
#: mixed samples and the occluders, the mixed samples are not warped and still occlude)
RULES = {"strict": (0.0, 3, False, False, False), "midpoint": (0.5, 0, False, False, False),
         "mixed": (0.0, 3, True, False, False), "strict-fg": (0.0, 3, False, True, False),
         "mixed-fg": (0.0, 3, True, True, False), "footprint-fg": (0.0, FOOTPRINT_BAND_PX, False, True, True),
         "footprint-mixed-fg": (0.0, FOOTPRINT_BAND_PX, True, True, True),
         "footprint-colour-fg": (0.0, FOOTPRINT_BAND_PX, False, True, True)}
#: the rules that also mask by the LQ colour image (:func:`colour_edge_mask`)
COLOUR_RULES = frozenset({"footprint-colour-fg"})
#: :func:`colour_edge_mask`'s margin (RGB distance, 0-255 per channel), chosen on the demo and seed 1 (40 / 60 / 80:
#: the largest catch that keeps both within 2 % masked) and checked on seeds 2, 4-9 (``docs/reference_edges.md``)
COLOUR_EDGE_MARGIN = 60.0
#: the relative depth difference that puts a neighbour on the same surface / across a silhouette for the colour test
COLOUR_EDGE_REL = 0.1
#: the footprint occluders' reach, in HQ pixel footprints (:func:`footprint_occluders`), and the depth step
#: (relative) behind an occluder that hides a reference pixel
OCCLUDER_REACH = 2.5
OCCLUDER_REL = 0.1
#: the largest splat offset of an occluder, destination pixels
MAX_OCCLUDER_PX = 3


@dataclass(frozen=True)
class EdgeRule:
    """How the reference treats depth edges.

    Attributes:
        name: a key of :data:`RULES`: ``"strict"``, ``"midpoint"`` (the plain warp), ``"mixed"``,
            ``"strict-fg"``, ``"mixed-fg"``, ``"footprint-mixed-fg"``, ``"footprint-fg"`` (the default of the aligned dataset:
            :class:`align.pair_reference.ReferenceOptions`).
        edge_reach: the warp's reach past a surface's last sample, source-grid steps, ``[0, 1)``.
        mask_px: far side of a reference edge masked within this many destination pixels (0: none).
        edge_rel: relative depth jump that makes an edge (0.03 = 3 %).
        mixed: the HQ samples :func:`align.mixed_pixels.mixed_samples` distrusts are not warped as
            surface samples; their footprint, at the nearest depth around them, is masked and hides
            what lies behind it (:meth:`warp`).
        k_sigma: the mixed-sample test's threshold (standard deviations).
        scored_only: the band (:meth:`apply`) masks only pixels whose reference is in front of the
            background (:func:`align.roi.in_front`, the ROI's test), where the leaderboard would score
            it; a pixel the reference puts on the background is outside the ROI whatever it holds, and
            masking it would only hand it to the LQ depth, which decides the ROI where the reference
            has none (``"strict-fg"``, ``"mixed-fg"``; the module docstring's last table).
        occluders: every finite HQ sample, those the warp drops at edges (mixes, isolated samples) included,
            hides what lies behind its footprint (:func:`footprint_occluders`, ``OCCLUDER_REACH`` footprints
            wide): reference pixels more than ``OCCLUDER_REL`` behind it are masked (``"footprint-fg"``).
        colour_edge: the LQ colour image masks what it shows on the other side of a reference silhouette
            (:meth:`colour_mask`, :func:`colour_edge_mask`; ``"footprint-colour-fg"``).
    """

    name: str = "strict"
    edge_reach: float = 0.0
    mask_px: int = 3
    edge_rel: float = 0.03
    mixed: bool = False
    k_sigma: float = 3.0
    scored_only: bool = False
    occluders: bool = False
    colour_edge: bool = False

    @classmethod
    def named(cls, name: str, *, edge_rel: float = 0.03) -> "EdgeRule":
        if name not in RULES:
            raise OptionError(f"reference edge rule must be one of {', '.join(RULES)}, got {name!r}",
                              option="reference_edges")
        reach, mask_px, mixed, scored_only, occluders = RULES[name]
        return cls(name=name, edge_reach=reach, mask_px=mask_px, edge_rel=edge_rel, mixed=mixed, scored_only=scored_only,
                   occluders=occluders, colour_edge=name in COLOUR_RULES)

    def warp(self, warper, hq: np.ndarray, *, motion=None,
             background: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """One HQ frame ``(h, w)`` float32 metres warped by ``warper`` (:class:`align.warp.DepthWarper`
        built with :attr:`edge_reach`) as the rule wants it: ``(depth, mask)``, ``mask`` the pixels the
        rule set to NaN at this step (``None``: none; every rule but ``"mixed"`` returns the plain warp,
        the same array the warper gives). ``motion``: the HQ points moved before every warp
        (:meth:`align.warp.DepthWarper.warp`'s; scene flow to the LQ instant), ``None``: not moved.

        ``"mixed"``: two warps, one without the distrusted samples (the reference) and one with them
        at the nearest depth around them; where the second has a surface the first lacks or has
        farther, and on the far side of the second's edges (:func:`occluded_side`), the reference is
        masked. ``mask``: the pixels where the plain warp (a third one) has depth and the result has
        none, so that the count compares with the other rules'. With :attr:`scored_only` and a
        ``background`` (the ROI's, on the destination image), a pixel whose value (the reference's, else
        the plain warp's) is not in front of the background keeps it.

        :attr:`occluders` (``"footprint-fg"``): the plain warp, with the pixels more than ``OCCLUDER_REL`` behind
        :func:`footprint_occluders` of the same frame masked (with :attr:`scored_only` and a ``background``, only
        those in front of it); ``mask``: those pixels.
        """
        if self.occluders:
            return self._footprint_warp(warper, hq, motion=motion, background=background)
        if not self.mixed:
            return warper(hq, motion=motion), None
        hq = np.asarray(hq, np.float32)
        bad = mixed_samples(hq, edge_rel=self.edge_rel, k_sigma=self.k_sigma)
        ref = warper(np.where(bad, np.float32(np.nan), hq), motion=motion)
        occluders = warper(np.where(bad, nearest_around(hq), hq), motion=motion)
        with np.errstate(invalid="ignore"):
            hidden = np.isfinite(occluders) & ~(np.abs(ref - occluders) <= self.edge_rel * occluders)
        hide = hidden | occluded_side(occluders, radius_px=self.mask_px, edge_rel=self.edge_rel)
        scored = self.scored_only and background is not None
        if scored:
            hide &= in_front(ref, background)
        out = np.where(hide, np.float32(np.nan), ref).astype(np.float32, copy=False)
        plain = warper(hq, motion=motion)
        if scored:
            out = np.where(~np.isfinite(out) & ~in_front(plain, background), plain, out).astype(np.float32, copy=False)
        return out, np.isfinite(plain) & ~np.isfinite(out)

    def _footprint_warp(self, warper, hq: np.ndarray, *, motion, background) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`warp` for the rules with :attr:`occluders`: the plain warp, the pixels more than ``OCCLUDER_REL``
        behind :func:`footprint_occluders` masked (with :attr:`scored_only` and a ``background``, only those in front
        of it). With :attr:`mixed` (``"footprint-mixed-fg"``) the samples :func:`align.mixed_pixels.mixed_samples`
        distrusts are not warped, and the pixels the plain warp had where the result has none are masked too
        (counted, as the ``"mixed"`` rule counts them; a pixel the ROI would not score keeps the plain value);
        the occluders still come from every sample. Returns ``(depth, mask)``."""
        hq = np.asarray(hq, np.float32)
        ref, fmap = warper.warp_with_map(hq, motion=motion)
        occ = footprint_occluders(warper, hq, motion=motion, forward_map=fmap)
        scored = self.scored_only and background is not None
        dropped = None
        if self.mixed:
            plain = ref.copy()
            bad = mixed_samples(hq, edge_rel=self.edge_rel, k_sigma=self.k_sigma)
            ref = warper(np.where(bad, np.float32(np.nan), hq), motion=motion)
            dropped = np.isfinite(plain) & ~np.isfinite(ref)
            if scored:
                keep = dropped & ~in_front(plain, background)
                ref = np.where(keep, plain, ref)
                dropped &= ~keep
        with np.errstate(invalid="ignore"):
            hide = ref - occ > OCCLUDER_REL * occ
        if scored:
            hide &= in_front(ref, background)
        if dropped is not None:
            hide |= dropped
        return np.where(hide, np.float32(np.nan), ref).astype(np.float32, copy=False), hide

    def apply(self, reference: np.ndarray, *, background: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The reference ``(H, W)`` float32 metres with the rule's mask set to NaN, and the mask.

        ``background``: ``(H, W)`` float32 metres, the ROI's background model
        (:func:`align.roi.background_depth`); with :attr:`scored_only` the band keeps the pixels whose
        reference is not in front of it. ``None``: the band everywhere."""
        if self.mask_px <= 0:
            return reference, np.zeros(reference.shape, bool)
        mask = occluded_side(reference, radius_px=self.mask_px, edge_rel=self.edge_rel)
        if self.scored_only and background is not None:
            mask &= in_front(reference, background)
        return np.where(mask, np.float32(np.nan), reference).astype(np.float32, copy=False), mask

    def colour_mask(self, reference: np.ndarray, color: np.ndarray | None, *,
                    background: np.ndarray | None = None) -> np.ndarray:
        """The pixels ``(H, W)`` bool the LQ colour image masks in ``reference`` (:func:`colour_edge_mask`; with
        :attr:`scored_only` and a ``background``, only those in front of it). No pixel where the rule has no
        :attr:`colour_edge` or ``color`` is ``None`` (no co-registered LQ colour)."""
        if not self.colour_edge or color is None:
            return np.zeros(np.shape(reference), bool)
        mask = colour_edge_mask(reference, color)
        if self.scored_only and background is not None:
            mask &= in_front(reference, background)
        return mask

    def to_dict(self) -> dict:
        d = {"rule": self.name, "edge_reach": self.edge_reach, "mask_px": self.mask_px, "edge_rel": self.edge_rel}
        d = {**d, "colour_edge": {"margin": COLOUR_EDGE_MARGIN, "rel": COLOUR_EDGE_REL}} if self.colour_edge else d
        d = {**d, "scored_only": True} if self.scored_only else d
        d = {**d, "occluders": {"reach_footprints": OCCLUDER_REACH, "rel": OCCLUDER_REL}} if self.occluders else d
        return {**d, "mixed_samples": {"k_sigma": self.k_sigma}} if self.mixed else d


def colour_edge_score(reference: np.ndarray, color: np.ndarray, *, rel: float = COLOUR_EDGE_REL) -> np.ndarray:
    """How much the LQ colour of each reference pixel looks like the other side of a reference silhouette.

    ``reference`` ``(H, W)`` float32 metres (NaN = none), ``color`` ``(H, W, 3)`` uint8 co-registered with it. For a
    pixel ``p`` with depth, ``a_in`` is the smallest RGB distance from ``c(p)`` to an 8-neighbour on ``p``'s surface
    (depth within ``rel`` of ``z(p)``; ``sqrt(3) * 255`` if there is none) and ``a_out`` the smallest to an
    8-neighbour across a silhouette (a hole, or farther than ``(1 + rel) z(p)``). Returns ``a_in - a_out``
    ``(H, W)`` float32, NaN where ``p`` has no depth or no neighbour across a silhouette. Image borders count as
    neither side. A near surface's pixel that the LQ camera sees on the far side of the silhouette (the reference
    one HQ step too far at a concave corner, or across a slit the HQ samples miss) has the far side's colour.

    Example:
        >>> z = np.array([[1.0, 1.0, np.nan]], np.float32)
        >>> c = np.array([[[200, 0, 0], [0, 0, 200], [0, 0, 200]]], np.uint8)
        >>> s = colour_edge_score(z, c)
        >>> np.isnan(s[0, [0, 2]]).tolist(), round(float(s[0, 1]), 1)
        ([True, True], 282.8)
    """
    z = np.asarray(reference, np.float32)
    c = np.asarray(color, np.float32)
    H, W = z.shape
    zp = np.pad(z, 1, constant_values=np.nan)
    fp = np.pad(np.ones((H, W), bool), 1, constant_values=False)
    cp = np.pad(c, ((1, 1), (1, 1), (0, 0)))
    a_in = np.full((H, W), np.float32(np.sqrt(3.0) * 255.0))
    a_out = np.full((H, W), np.inf, np.float32)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di == 0 and dj == 0:
                continue
            zn, inside = zp[1 + di:1 + di + H, 1 + dj:1 + dj + W], fp[1 + di:1 + di + H, 1 + dj:1 + dj + W]
            d = np.sqrt(np.sum((cp[1 + di:1 + di + H, 1 + dj:1 + dj + W] - c) ** 2, axis=2))
            with np.errstate(invalid="ignore"):
                same = inside & (np.abs(zn - z) <= rel * z)
                across = inside & (~np.isfinite(zn) | (zn > (1 + rel) * z))
            a_in = np.where(same, np.minimum(a_in, d), a_in)
            a_out = np.where(across, np.minimum(a_out, d), a_out)
    out = a_in - a_out
    out[~np.isfinite(z) | ~np.isfinite(a_out)] = np.nan
    return out.astype(np.float32)


def colour_edge_mask(reference: np.ndarray, color: np.ndarray, *, margin: float = COLOUR_EDGE_MARGIN,
                     rel: float = COLOUR_EDGE_REL) -> np.ndarray:
    """Reference pixels ``(H, W)`` bool whose :func:`colour_edge_score` is at least ``margin``: the LQ colour
    image says they lie on the other side of the silhouette the reference puts next to them."""
    with np.errstate(invalid="ignore"):
        return colour_edge_score(reference, color, rel=rel) >= margin


def _near_an_edge(d: np.ndarray, *, edge_rel: float) -> np.ndarray:
    """``(h, w)`` bool: samples within one pixel (3x3) of a sample that has a 3x3 neighbour missing or farther by
    more than ``edge_rel``."""
    k = np.ones((3, 3), np.uint8)
    far = cv2.dilate(np.where(np.isfinite(d), d, np.inf).astype(np.float32), k, borderType=cv2.BORDER_REPLICATE)
    with np.errstate(invalid="ignore"):
        edge = np.isfinite(d) & ~(far - d <= edge_rel * d)
    return cv2.dilate(edge.astype(np.uint8), k).astype(bool)


def footprint_occluders(warper, hq: np.ndarray, *, reach: float = OCCLUDER_REACH, motion=None,
                        edges_only: bool = True, forward_map: tuple | None = None) -> np.ndarray:
    """The nearest depth ``(H, W)`` float32 metres (``inf``: none) any HQ sample of ``hq`` (``(h, w)`` float32
    metres, NaN = none) puts on each destination pixel through its footprint, ``reach`` footprints wide.

    Every finite sample counts, also those the warp drops (mixes and isolated samples at edges, which the warp
    cannot link into a surface): a sample is evidence that something at most that far lies within its pixel.
    The sample projects to ``(u, v)`` at depth ``z`` (:meth:`align.warp.DepthWarper.forward_map`, with
    ``motion`` as :meth:`~align.warp.DepthWarper.warp`'s) and covers the destination pixels within ``R``
    (Chebyshev) of the pixel nearest to ``(u, v)``, ``R = round(0.5 * reach * fx_dst / fx_src)`` (at least 1, at
    most ``MAX_OCCLUDER_PX``): a z-buffer of the samples at their nearest pixels, then a ``(2R+1)^2`` minimum.
    ``edges_only`` (the default): only the samples within one pixel of an HQ depth edge or hole (a 3x3
    neighbour missing or farther by more than the warper's ``edge_rel``) splat; inside a surface the warp's own
    z-buffer already hides what lies behind it. ``forward_map``: ``warper.forward_map(hq, motion=motion)`` where the
    caller has it already (:meth:`~align.warp.DepthWarper.warp_with_map`).

    Example:
        >>> from align.warp import DepthWarper
        >>> from capture.camera import Intrinsics, Transform
        >>> K = Intrinsics(8, 6, 10.0, 10.0, 3.5, 2.5)
        >>> hq = np.full((6, 8), 2.0, np.float32); hq[2, 3] = 1.0
        >>> occ = footprint_occluders(DepthWarper(K, K, Transform.identity()), hq, reach=2.0, edges_only=False)
        >>> float(occ[2, 3]), float(occ[3, 4]), float(occ[2, 5]), float(occ[0, 0])
        (1.0, 1.0, 2.0, 2.0)
    """
    u, v, w, valid = warper.forward_map(hq, motion=motion) if forward_map is None else forward_map
    d = np.asarray(hq, np.float32)
    with np.errstate(invalid="ignore"):
        ok = valid & np.isfinite(u) & np.isfinite(v) & (w > 0) & np.isfinite(d) & (d > 0)
    if edges_only:
        ok &= _near_an_edge(d, edge_rel=warper.edge_rel)
    K_src, K_dst = warper.K_src, warper.K_dst
    cu, cv, z = np.round(u[ok]).astype(np.intp), np.round(v[ok]).astype(np.intp), np.float32(1) / w[ok]
    inside = (cu >= 0) & (cv >= 0) & (cu < K_dst.width) & (cv < K_dst.height)
    points = np.full(K_dst.shape, np.inf, np.float32)
    np.minimum.at(points, (cv[inside], cu[inside]), z[inside])
    R = int(min(max(round(0.5 * reach * K_dst.fx / K_src.fx), 1), MAX_OCCLUDER_PX))
    return cv2.erode(points, np.ones((2 * R + 1, 2 * R + 1), np.uint8), borderType=cv2.BORDER_CONSTANT,
                     borderValue=np.inf)


def occluded_side(depth: np.ndarray, *, radius_px: int = 2, edge_rel: float = 0.03) -> np.ndarray:
    """Pixels ``(H, W)`` bool with depth that lie within ``radius_px`` (a disc) of a pixel at least
    ``edge_rel`` of their depth nearer: the far side of every depth edge. NaN is no depth.

    Example:
        >>> z = np.full((1, 6), 2.0, np.float32); z[0, :2] = 1.0
        >>> occluded_side(z, radius_px=2).astype(int).tolist()
        [[0, 0, 1, 1, 0, 0]]
    """
    z = np.asarray(depth, np.float32)
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius_px + 1, 2 * radius_px + 1))
    nearest = cv2.erode(np.where(np.isfinite(z), z, np.inf).astype(np.float32), disc,
                        borderType=cv2.BORDER_CONSTANT, borderValue=np.inf)
    with np.errstate(invalid="ignore"):
        return np.isfinite(z) & (z - nearest > edge_rel * nearest)
