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

Measured on a demo-like session (``capture simulate --rig lq-hq --scene people --seconds 3
--seed 0``, scale 1, the smooth figures):

=====================================  ==============  ==============
HQ sensor against truth                midpoint        strict
=====================================  ==============  ==============
MAE / RMSE, leaderboard (90 frames)    6.32 / 69.6 mm  2.26 / 8.09 mm
pixels > 50 mm off, truth geometry     0.73 %          0.043 %
ROI pixels masked by the rule          0               2.9 %
ROI pixels without reference (all)     6.5 %           12.6 %
=====================================  ==============  ==============

(``perf/reference_error.py`` for rows 2-4, 6 pairs with truth's geometry; ``bench run`` for row 1.)
The cost is the masked band (2.9 % of the ROI) plus the gap no sample covers (3.2 %). What is
left (RMSE still 3.6x MAE) is the silhouette position inside one HQ step next to holes of the
reference (the large errors left lie within 2 px of a hole, 83 % with the reference nearer),
which no rule on the HQ depth alone can recover; masking the near side of such edges as well
bought RMSE 8.9 mm for another 2.8 % of the ROI and is not done. ``"midpoint"`` keeps the plain
warp: guess, mask nothing.

Traced further on the demo (scale 0.5, issue 12): after the strict rule, 96 % of the reference's
squared error comes from 0.02 % of its ROI pixels, each off by more than 0.3 m (a surface the LQ
camera does not see there); the same warp of the noise-free HQ depth has almost none of them. They
are the HQ sensor's time-of-flight mixed samples (:mod:`align.mixed_pixels`): a mix near one surface
warped as that surface one HQ step off the silhouette, or a near surface's mixed last samples dropped
so that the background the HQ camera saw beside it shows through inside the LQ silhouette, beyond the
3 px band. ``"mixed"`` (not the default) drops the mixed samples it can tell (off their surface's
line by more than 3 noise deviations, or isolated) and masks what their footprint, at the nearest
depth around them, hides. ``perf/reference_error.py``, 30 pairs, truth's geometry, mean over frames
(the leaderboard's "HQ sensor" column):

=====================  ==========================  ==========================
demo-like session      strict: MAE / RMSE, masked  mixed: MAE / RMSE, masked
=====================  ==========================  ==========================
seed 0 (the demo)      2.45 / 10.46 mm, 3.6 %      2.16 / 4.93 mm, 7.6 %
seed 1 (held out)      2.49 / 12.87 mm, 3.7 %      2.28 / 8.80 mm, 7.1 %
seed 2 (held out)      2.35 / 9.21 mm, 3.2 %       2.13 / 4.77 mm, 6.9 %
seed 3 (held out)      2.48 / 10.29 mm, 3.6 %      2.24 / 7.12 mm, 7.9 %
=====================  ==========================  ==========================

"masked": ROI pixels where the plain warp has depth and the reference none. What ``"mixed"`` leaves
(80-96 % of the squared error still from pixels > 0.3 m off) are mixes within the noise of one
surface, which no test on their value can tell from a true last sample, and structures thinner than
one HQ step (a 1-LQ-pixel gap between limbs); only a band along every silhouette would remove them.

The band's width against its cost (demo, 30 pairs, session 6): strict with a 1 / 2 / 3 px band masks
1.6 / 2.8 / 3.6 % of the ROI for RMSE / MAE 8.0 / 6.2 / 4.3; mixed with 0 / 1 / 2 / 3 px, 4.9 / 5.7 / 6.5 /
7.6 % for 7.3 / 6.6 / 3.6 / 2.3. Masking only the side of an edge away from the HQ camera (the side its
far samples can intrude on, through the 12.5 cm baseline) keeps 3.2 of the 3.6 %: the band is spent
where it is needed, the other side is holes already. Masking only one HQ step at the near depth beyond
each edge (1.7 %) leaves RMSE / MAE 7.7: the intrusions are deeper, where the last near samples were mixed.

**Masking only what is scored (``"strict-fg"``, ``"mixed-fg"``; issue 12, session 8).** The ROI is
computed from the reference, with the LQ depth where the reference has none
(:func:`align.pipeline.write_pair_dataset`). Traced on the demo (30 pairs), every pixel more than 0.3 m
off that the strict rule's band is there to remove lies on a surface that is itself in front of the
background (one person seen through the edge of another, at 2.8-3.7 m against a 5 m wall): far
samples of the wall that land inside a silhouette read as background and are outside the ROI whatever
is done with them. Masking them only hands them to the LQ depth, whose stereo edge fattening puts them
back into the ROI, unscored against the reference but scored against the truth (the pixels that flip
the leaderboard's order, ``perf/reference_ranking.py``). The ``-fg`` rules mask as their base rule but
only where the reference is in front of the ROI's background model (:func:`align.roi.in_front`; the
``mixed`` rule's warp keeps the plain warp's value where that is background). They need that model,
which ``align`` computes from the references before it writes them; without it they mask as their base.
``perf/reference_error.py SESSION --frames 30`` (truth's geometry, per-frame means as the leaderboard's
"HQ sensor"; "masked": ROI pixels where the rule's warp has depth and the reference none):

==================  =====================  =====================  =====================  =====================
session             strict: RMSE/MAE, mask strict-fg               mixed                  mixed-fg
==================  =====================  =====================  =====================  =====================
demo (seed 0)       11.57/2.70, 3.64 %     11.55/2.69, 1.28 %     5.95/2.36, 7.96 %      5.94/2.36, 5.38 %
seed 1 (held out)   11.82/2.74, 4.11 %     11.82/2.74, 1.08 %     7.92/2.48, 7.92 %      7.93/2.48, 4.58 %
seed 2 (held out)   11.89/2.67, 3.64 %     11.34/2.65, 1.00 %     5.78/2.38, 7.56 %      5.76/2.37, 4.63 %
seed 3 (held out)   11.51/2.31, 3.29 %     11.49/2.31, 1.19 %     5.93/2.06, 6.97 %      5.93/2.06, 4.62 %
seed 4 (held out)   12.98/2.54, 3.53 %     12.91/2.53, 0.98 %     5.38/2.19, 7.10 %      5.36/2.18, 4.26 %
==================  =====================  =====================  =====================  =====================

(held-out sessions: ``capture simulate --rig lq-hq --scene people --seconds 2 --seed S --scale 0.5
--time-shift-ms 25 --frame-phase-ms 1``, the demo's with its frames ~1 ms apart; seed 3 without the
phase option.) Same errors, a third (strict) or three fifths (mixed) of the masked share. Through
``align`` itself (its fit, 60 frames) and the leaderboard's "HQ sensor" column (RMSE / MAE with its 95 %
bootstrap interval over frames; ROI masked as ``aligned.json`` counts it):

==================  ===================  ===================  ===================
session             strict               strict-fg            mixed-fg
==================  ===================  ===================  ===================
demo (seed 0)       3.52, 3.81 %         3.52, 1.35 %         1.98 [1.61, 2.47], 5.43 % (mixed: 8.12 %)
seed 1 (held out)   4.51, 3.69 %         4.49, 1.04 %         3.29 [2.36, 4.46], 4.60 %
seed 2 (held out)   4.15, 3.02 %         4.13, 0.94 %         2.13 [1.63, 2.73], 4.61 %
seed 4 (held out)   3.15, 3.53 %         3.14, 0.94 %         1.89 [1.43, 2.48], 4.22 %
==================  ===================  ===================  ===================

So neither meets issue 12's pair (RMSE within 2x MAE at no more than 2 % masked): ``strict-fg`` keeps
the mask under 2 % and the ratio at 3-4.5, ``mixed-fg`` brings the ratio to about 2 at 4-5.5 %. Cost:
``strict-fg`` adds one comparison per pixel (60 references of the demo: 0.33 against 0.31 CPU-s),
``mixed-fg`` three warps per frame, as ``mixed`` (1.25 CPU-s; ~2 CPU-s more per ``align`` of the demo,
whose step takes ~20). What is
left of the RMSE is not the band: 75-90 % of the squared error comes from a few pixels a whole jump off
next to a hole of the reference, the time-of-flight mixes :mod:`align.mixed_pixels` cannot tell from
true samples (and the ``mixed`` rule's removal of the ones it can tell costs 3.5 % of the ROI, of which
3 % were right). Colour does not tell them apart either on these scenes: the HQ colour image, seen at
either candidate depth, names the side of an HQ edge sample wrongly in 27-34 % of cases
(``notes/refedge_scripts/colfeas.py``; the surfaces' random colour mosaic looks alike on both sides).

**Footprint occluders (``"footprint-fg"``, the default; issue 12, session 9).**
Traced on the demo (``strict-fg``, 60 frames): 71 ROI pixels of 452 232 are off by more than 0.3 m, and masking
them alone would bring the ratio from 3.52 to 1.75. Two kinds. *Reference farther* (about two thirds): a
nearer surface's last HQ samples are mixes or isolated samples the warp cannot link into a surface (a person's
side at a grazing angle), so the nearer surface ends in the reference several pixels short, and the samples
of the mid-ground surface the HQ camera saw beside it fill the gap inside the LQ silhouette; the band misses
them, since no nearer *reference* pixel lies within 3 px. The dropped samples are still evidence that
something that near lies within their pixel: :func:`footprint_occluders` splats every HQ sample near an edge
over its footprint (2.5 footprints wide), and ``"footprint-fg"`` masks reference pixels more than 10 % behind
it (in front of the background, as ``strict-fg``). *Reference nearer* (the rest): a gap between two limbs or
people thinner than one HQ step from the HQ camera's side (the HQ depth shows one continuous surface, the LQ
camera sees the wall through a 1-2 px slit), or a near surface's last sample's splat one pixel past a
diagonal silhouette. The HQ depth holds nothing that tells these apart from a true surface pixel, in this
frame or the neighbouring ones (the two neighbouring HQ frames, warped alike, vote against none of the 71).
Through ``align`` (60 frames, the leaderboard's "HQ sensor" RMSE / MAE with its 95 % bootstrap interval over
frames; masked as ``aligned.json`` counts it; ``notes/refedge9_scripts/hqsensor.py``):

==================  ===========================  ===========================
session             strict-fg                    footprint-fg
==================  ===========================  ===========================
demo (seed 0)       3.52 [2.80, 4.30], 1.35 %    2.85 [2.25, 3.54], 1.53 %
seed 1 (held out)   4.49 [3.31, 5.68], 1.04 %    4.45 [3.33, 5.65], 1.13 %
seed 2 (held out)   4.13 [3.12, 5.21], 0.94 %    3.19 [2.51, 3.91], 1.12 %
seed 4 (held out)   3.14 [2.32, 4.15], 0.94 %    2.38 [1.95, 2.87], 1.05 %
==================  ===========================  ===========================

The ratio falls on every held-out session (paired bootstrap over frames, footprint-fg - strict-fg: seed 1
-0.03 [-0.09, 0.00], seed 2 -0.93 [-1.77, -0.20], seed 4 -0.76 [-1.51, -0.17]; demo -0.67 [-1.17, -0.23];
``notes/refedge9_scripts/paired_ratio.py``), so it is the default (``strict-fg`` was, for part of session 9).
With the photometric keypoint refinement of T_lq_hq (its +1.1 mm z error gone; the MAE falls, so the ratio rises):
demo strict-fg 4.11 [3.22, 4.98] at 1.35 %, footprint-fg 3.44 [2.66, 4.32] at 1.54 % (paired -0.67 [-1.18, -0.21]);
the 27 pixels left > 0.3 m off are all of the second kind. With the warp's diagonal cut (:mod:`align.warp`
step 4, :func:`align.warp_splat.diagonal_cuts`) 3.10 [2.41, 3.92] at 1.50 % (paired -0.34 [-0.76, -0.03]; held
out seed 1 4.66 -> 4.57, seed 2 3.57 -> 3.38, seed 4 2.96 -> 2.84, each paired interval below 0); 6 of those 27
became holes, 21 are left. Truth's geometry (``perf/reference_error.py demo
--frames 30``): strict-fg 4.29 at 1.28 %, footprint-fg 3.67 at 1.45 %.
Cost: :func:`footprint_occluders` 2.0 ms CPU per demo frame beside the plain warp's 2.2 ms; ``align`` of the
demo 21.7 CPU-s against 21.9 with ``strict-fg`` (one run each, noise ~1 s).

**What is left, and the trade (``"footprint-mixed-fg"``, opt-in; issue 12, session 10).** The 21 demo pixels
still more than 0.3 m off (``footprint-fg``), traced to the HQ samples whose splats cover them against the HQ
truth (``docs/worklog/2026-11-24-s10/refedge3.md``): 14 are covered by a time-of-flight mix on the far side of a
silhouette whose value lies within the warp's continuity test of the near surface (3 % jump, 1 % slope), so it is
warped as the near surface one HQ step too far; 5 by a full grid cell of true near samples (the LQ camera sees
through a slit thinner than one HQ step, or at the tip of a closing gap between limbs that moves a pixel in the
~0.5 ms between the two exposures); 2 by the triangle of a cell cut at the diagonal where the silhouette is
concave. Held-out seeds 1 / 2 / 4 alike (27 / 17 / 11 mixes, 20 / 4 / 8 full cells, 5 / 2 / 1 triangles). No
test on the HQ depth marks the last two kinds (all 21 pixels pass the visibility test: the reference's 3D point
seen from the HQ camera lies on the HQ depth there). The mixes can be told from true samples only statistically:
:func:`align.mixed_pixels.mixed_samples` flags 11 of the 14 (off their surface's line by more than 3 noise
deviations), and with them a few percent of true edge samples. ``"footprint-mixed-fg"`` is ``"footprint-fg"``
with those samples not warped (they still occlude); the pixels the plain warp had there are masked and counted,
as ``"mixed"`` counts them. Through ``align`` (60 frames; masked as ``aligned.json`` counts it):

==================  ============================  ============================  ============================
session             footprint-fg                  footprint-mixed-fg            mixed-fg
==================  ============================  ============================  ============================
demo (seed 0)       3.10 [2.41, 3.92], 1.50 %     1.97 [1.66, 2.41], 4.33 %     1.86 [1.61, 2.23], 5.34 %
seed 1 (held out)   4.57 [3.47, 5.77], 1.10 %     3.23 [2.22, 4.38], 3.69 %     3.22 [2.19, 4.38], 4.53 %
seed 2 (held out)   3.38 [2.68, 4.14], 1.09 %     2.21 [1.69, 2.89], 3.72 %     2.21 [1.68, 2.91], 4.50 %
seed 4 (held out)   2.84 [2.20, 3.64], 1.03 %     2.02 [1.61, 2.54], 3.42 %     2.06 [1.60, 2.65], 4.13 %
==================  ============================  ============================  ============================

Paired against ``"mixed-fg"`` the ratio is the same within noise on every session (demo +0.11 [-0.04, +0.36],
seeds 1 / 2 / 4 +0.01 / +0.00 / -0.04, each interval across 0) at 0.7-1.0 points less of the ROI masked: the
mixes' footprints need not be masked when the footprint occluders already hide what lies behind them. Neither
meets issue 12's pair (ratio within 2 at no more than 2 % masked); the default stays ``"footprint-fg"``. Even an
oracle that masked every triangle and full-cell pixel above 0.3 m (truth-chosen) would leave the demo at 2.42 and
seed 1 at 3.42: the mixes within the noise must go too, and the HQ depth holds nothing that tells them apart.
Cost: 8.0 ms CPU per demo frame against ``"footprint-fg"``'s 2.3 (:func:`align.mixed_pixels.mixed_samples` and a
second warp). The demo's leaderboard (``bench run`` with raw, BF, JBF, RGF) on a ``"footprint-mixed-fg"`` dataset:
HQ sensor RMSE / MAE 4.59 / 2.33 mm, and the reference ranks the methods as the truth does (same order by MSE and
by RMSE, each of the 12 pair-metric differences with the same sign). All of this was measured on sessions
simulated with the uniform time-of-flight mixes of :mod:`capture.sim.noise` (``flying_mix = "uniform"``); with
the coverage law, the simulator's default since session 10, ``"footprint-fg"`` reads 2.63 [1.98, 3.34] at
1.79 % masked on the demo (held-out seeds 1 / 2 / 4: 4.02 / 2.79 / 2.47; ``simtof.md``).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from align.errors import OptionError
from align.mixed_pixels import mixed_samples, nearest_around
from align.roi import in_front

#: the named rules: (edge reach of the warp, mask width in destination pixels, HQ mixed samples as occluders,
#: the band only where the reference is scored, every HQ sample's footprint as an occluder; with both the
#: mixed samples and the occluders, the mixed samples are not warped and still occlude)
RULES = {"strict": (0.0, 3, False, False, False), "midpoint": (0.5, 0, False, False, False),
         "mixed": (0.0, 3, True, False, False), "strict-fg": (0.0, 3, False, True, False),
         "mixed-fg": (0.0, 3, True, True, False), "footprint-fg": (0.0, 3, False, True, True),
         "footprint-mixed-fg": (0.0, 3, True, True, True)}
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
    """

    name: str = "strict"
    edge_reach: float = 0.0
    mask_px: int = 3
    edge_rel: float = 0.03
    mixed: bool = False
    k_sigma: float = 3.0
    scored_only: bool = False
    occluders: bool = False

    @classmethod
    def named(cls, name: str, *, edge_rel: float = 0.03) -> "EdgeRule":
        if name not in RULES:
            raise OptionError(f"reference edge rule must be one of {', '.join(RULES)}, got {name!r}",
                              option="reference_edges")
        reach, mask_px, mixed, scored_only, occluders = RULES[name]
        return cls(name=name, edge_reach=reach, mask_px=mask_px, edge_rel=edge_rel, mixed=mixed, scored_only=scored_only,
                   occluders=occluders)

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
        ref = warper(hq, motion=motion)
        occ = footprint_occluders(warper, hq, motion=motion)
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

    def to_dict(self) -> dict:
        d = {"rule": self.name, "edge_reach": self.edge_reach, "mask_px": self.mask_px, "edge_rel": self.edge_rel}
        d = {**d, "scored_only": True} if self.scored_only else d
        d = {**d, "occluders": {"reach_footprints": OCCLUDER_REACH, "rel": OCCLUDER_REL}} if self.occluders else d
        return {**d, "mixed_samples": {"k_sigma": self.k_sigma}} if self.mixed else d


def _near_an_edge(d: np.ndarray, *, edge_rel: float) -> np.ndarray:
    """``(h, w)`` bool: samples within one pixel (3x3) of a sample that has a 3x3 neighbour missing or farther by
    more than ``edge_rel``."""
    k = np.ones((3, 3), np.uint8)
    far = cv2.dilate(np.where(np.isfinite(d), d, np.inf).astype(np.float32), k, borderType=cv2.BORDER_REPLICATE)
    with np.errstate(invalid="ignore"):
        edge = np.isfinite(d) & ~(far - d <= edge_rel * d)
    return cv2.dilate(edge.astype(np.uint8), k).astype(bool)


def footprint_occluders(warper, hq: np.ndarray, *, reach: float = OCCLUDER_REACH, motion=None,
                        edges_only: bool = True) -> np.ndarray:
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
    z-buffer already hides what lies behind it.

    Example:
        >>> from align.warp import DepthWarper
        >>> from capture.camera import Intrinsics, Transform
        >>> K = Intrinsics(8, 6, 10.0, 10.0, 3.5, 2.5)
        >>> hq = np.full((6, 8), 2.0, np.float32); hq[2, 3] = 1.0
        >>> occ = footprint_occluders(DepthWarper(K, K, Transform.identity()), hq, reach=2.0, edges_only=False)
        >>> float(occ[2, 3]), float(occ[3, 4]), float(occ[2, 5]), float(occ[0, 0])
        (1.0, 1.0, 2.0, 2.0)
    """
    u, v, w, valid = warper.forward_map(hq, motion=motion)
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
