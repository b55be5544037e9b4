"""``align_session``: a session folder in, an aligned dataset (plus its report) out.

The I/O layer around the pure modules. Steps, in order:

1. **Fit** (:func:`fit_pair`, never reads ``truth/``): pick probe HQ frames spread over the
   session; per probe read the HQ colour and depth and the LQ colour frames around it, detect
   features once, match, lift to 3D, track (``align.time_shift.Probe``); search the time shift
   (``align.time_shift``); fit ``T_ex`` jointly over all probes (``align.extrinsics``).
2. **Associate** every HQ depth frame with an LQ depth frame at the found shift (eq. 28 or TUM's
   greedy matching), drop pairs whose time difference is too large or whose depth residual
   stands out (``align.residuals``), each with its reason (``pairs.csv``).
3. **Write** (:func:`write_pair_dataset`): warp the HQ depth onto the LQ depth image
   (``align.warp``), compute the region of interest (``align.roi``), write the aligned dataset
   (``align.dataset``) and the report (``align.report``).
4. **Attach truth** (simulated sessions only, after fitting, clearly separate): the LQ sensor's
   noise-free depth of each kept LQ frame becomes the ``truth_depth`` layer, so the benchmark
   can score against truth. The fit has no access to it (:class:`TruthSource` is created only
   after :func:`fit_pair` returned).

Multi-view sessions (roles ``view``, optionally ``hq``): the reference sensor is ``hq`` if
present, else the first view; every view is fitted against it (same machinery), the rig is
expressed in the reference's depth frame (``rig.json``), and each view gets its own aligned
dataset under ``OUT/<view>/``. With ``rig_refine`` (default: rigs without an HQ sensor) the feature
rig only seeds a joint refinement from every sensor's static depth (``align.rig_refine``: ICP of every sensor pair, a
pose graph, covariances scaled by its loops, the feature fits checked against it); ``rig.json``
then holds the refined rig with its sds, the feature rig, and the check's warnings, and every
view's dataset uses the refined transform. A view whose time shift colour features could not
determine (``view_sync``, default; or every view) then gets it from the depth of what moves, given
that rig (``align.view_sync``): its frames are paired at that shift and ``rig.json`` holds
``time_sync``.
"""
from __future__ import annotations

import json
import logging
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from align.association import associate, nearest_mapping, overlap_us
from align.clustered import grid_cells
from align.dataset import AlignedDatasetWriter
from align.errors import AlignError, AssociationError, FeatureError, OptionError, UnobservableError
from align.extrinsics import MIN_POINTS, ExtrinsicFit, RigCalibration, compose_rig, fit_extrinsics, pose_std
from align.features import FEATURES, Patches, detect, hq_patches, inverse_depth_gradient, lift, match, refine_offsets, track
from align.motion import motion_summary
from align.pair_reference import MOTION_MODELS, PairReferences, ReferenceOptions
from align.residuals import depth_residual, outliers, robust_summary
from align.reference_edges import EdgeRule
from align.roi import background_depth, foreground_mask
from align.timestamps import regularize
from align.time_shift import (DEFAULT_RANGE_US, Probe, ShiftEstimate, ShiftLoss, estimate_time_shift,
                              probe_window)
from align.warp import DepthWarper, register_color
from capture.camera import Intrinsics, Transform
from capture.session import Session, open_session
from depthbench.fsutil import atomic_write_json, staged_directory

log = logging.getLogger(__name__)


#: when a multi-view rig is refined from static depth (:class:`AlignOptions` ``rig_refine``)
RIG_REFINE = ("views", "always", "never")
#: which views of a multi-view rig get their time shift from depth (:class:`AlignOptions` ``view_sync``)
VIEW_SYNC = ("unobservable", "always", "never")


@dataclass(frozen=True)
class AlignOptions:
    """Everything ``depthbench align`` can change; units in the names.

    shift_range_ms: search Delta in [-r, +r] ms. shift_step_ms: coarse scan step.
    features: sift | orb | akaze. max_features: per image. detect_scale: images are resized by
    this factor for detection (coordinates stay full resolution); default: so that the shorter side
    is about 240 px, at most halved (SIFT's cost falls with the square), and full resolution where that
    would shrink it by less than :data:`FULL_RES_ABOVE`. probes: HQ frames used for the fit (more where
    they hold fewer than ``min_matches`` colour matches: :func:`draw_probes`; and where they still fit no pose).
    association: nearest (eq. 28) | greedy (TUM). max_dt_ms: largest |t_LQ - (t_HQ + Delta)| of
    a kept pair (default half the LQ frame period). residual_k: a pair whose depth residual lies
    more than k MAD-sigmas above the median is dropped. time_model: constant | linear.
    workers: threads for feature work. on_unobservable: error | flag (flag: Delta = declared or
    0, marked unobservable in aligned.json and the report). attach_truth: simulated sessions.
    motion: carry the reference to the LQ frame's instant from the two HQ frames around it
    (:mod:`align.motion`) for pairs at least ``motion_min_dt_ms`` apart; closer pairs keep the plain
    warp, bit for bit. motion_model: ``"flow"`` (the default: scene flow along the HQ colour images' optical
    flow, :mod:`align.motion_flow`; edges where a frame has no colour) or ``"edges"`` (:mod:`align.motion`).
    rig_refine: multi-view rigs only: refine the feature rig from the sensors' static depth
    (:mod:`align.rig_refine`): ``views`` (default) where the reference is a view (no HQ sensor: the
    views are fitted against another LQ view 1-1.5 m away, off by up to 118 mm on the simulator),
    ``always``, or ``never`` (the pairwise feature fits as they are). With an HQ reference the feature
    fits were within 6 mm of the simulator's extrinsics and the refinement 1.7-7.2 mm (within its sd),
    so they are kept there.
    refine_features: after a first fit of ``T_ex``, move every matched LQ keypoint (and its track) to where
    the HQ colour patch around its HQ keypoint lies in the LQ image (:func:`align.features.refine_offsets`),
    drop the keypoints that cannot be refined, and fit ``T_ex`` again (:func:`refine_probe_tracks`). The
    effect loop chooses its effects on the SIFT tracks and, where it accepts one, refits its final model
    (pose, shift and the accepted effects) on the refined tracks (``align.loop.run``).
    view_sync: multi-view rigs only: the time shift of a view against the rig's reference from the
    depth disagreement of what moves, given the calibrated rig (:mod:`align.view_sync`):
    ``unobservable`` (default: where colour features could not determine it, instead of the
    placeholder), ``always`` (every view), ``never``. Multi-view fits then go on past an unobservable
    feature shift; ``on_unobservable`` applies to what depth could not determine either.
    """

    shift_range_ms: float = DEFAULT_RANGE_US / 1000
    shift_step_ms: float = 2.0
    features: str = "sift"
    max_features: int = 1500
    detect_scale: float | None = None
    probes: int = 24
    association: str = "nearest"
    max_dt_ms: float | None = None
    residual_k: float = 6.0
    time_model: str = "constant"
    workers: int = 2
    on_unobservable: str = "error"
    attach_truth: bool = True
    report: bool = True
    roi_frames: int = 40
    edge_rel: float = 0.03
    min_matches: int = 60
    refine_features: bool = True
    progress: bool = True
    dejitter: bool = True
    board: str | None = None
    board_frames: int = 30
    loop: bool = True
    loop_correct_depth: bool = True
    reference_edges: str = "footprint-fg"
    motion: bool = True
    motion_min_dt_ms: float = 1.0
    motion_model: str = "flow"
    rig_refine: str = "views"
    view_sync: str = "unobservable"

    def check(self) -> None:
        if self.board is not None:
            from align.charuco import BoardSpec

            BoardSpec.parse(self.board)
        if not self.shift_range_ms > 0:
            raise OptionError(f"shift range must be positive, got {self.shift_range_ms:g} ms", option="shift_range_ms")
        if not 0 < self.shift_step_ms <= self.shift_range_ms:
            raise OptionError(f"shift step must be in (0, {self.shift_range_ms:g}] ms, got {self.shift_step_ms:g} ms",
                              option="shift_step_ms")
        if self.features not in FEATURES:
            raise OptionError(f"feature detector must be one of {', '.join(FEATURES)}, got {self.features!r}",
                              option="features")
        if self.association not in ("nearest", "greedy"):
            raise OptionError(f"association must be nearest or greedy, got {self.association!r}", option="association")
        if self.probes < 3:
            raise OptionError(f"probes must be at least 3, got {self.probes}", option="probes")
        if self.max_dt_ms is not None and not self.max_dt_ms > 0:
            raise OptionError(f"largest pair time difference must be positive, got {self.max_dt_ms:g} ms", option="max_dt_ms")
        if self.time_model not in ("constant", "linear"):
            raise OptionError(f"time model must be constant or linear, got {self.time_model!r}", option="time_model")
        EdgeRule.named(self.reference_edges)
        if not self.motion_min_dt_ms >= 0:
            raise OptionError(f"smallest motion-compensated time apart must be >= 0 ms, got {self.motion_min_dt_ms!r}",
                              option="motion_min_dt_ms")
        if self.motion_model not in MOTION_MODELS:
            raise OptionError(f"motion model must be one of {', '.join(MOTION_MODELS)}, got {self.motion_model!r}",
                              option="motion_model")
        if self.rig_refine not in RIG_REFINE:
            raise OptionError(f"rig refinement must be one of {', '.join(RIG_REFINE)}, got {self.rig_refine!r}",
                              option="rig_refine")
        if self.view_sync not in VIEW_SYNC:
            raise OptionError(f"view sync must be one of {', '.join(VIEW_SYNC)}, got {self.view_sync!r}",
                              option="view_sync")
        if self.on_unobservable not in ("error", "flag"):
            raise OptionError(f"on_unobservable must be 'error' or 'flag', got {self.on_unobservable!r}",
                              option="on_unobservable")


# --------------------------------------------------------------------------------------- geometry
def _stream_of_type(session: Session, sensor: str, kind: str) -> str | None:
    for name, s in session.sensors[sensor].streams.items():
        if s.type == kind:
            return name
    return None


@dataclass
class PairSetup:
    """Streams, cameras and timestamps of one (source = HQ, target = LQ) pair of a session."""

    session: Session
    lq: str
    hq: str
    lq_depth: str
    lq_color: str
    hq_depth: str
    hq_color: str
    K_lq: Intrinsics
    K_lq_color: Intrinsics
    K_hq: Intrinsics
    K_hq_color: Intrinsics
    T_lqdepth_lqcolor: Transform
    T_hqdepth_hqcolor: Transform
    t_lq: np.ndarray
    f_lq: np.ndarray
    t_lq_c: np.ndarray
    f_lq_c: np.ndarray
    t_hq: np.ndarray
    f_hq: np.ndarray
    t_hq_c: np.ndarray
    f_hq_c: np.ndarray
    hq_color_of_depth: np.ndarray  # per HQ depth frame: index of its colour frame, -1 if none
    lq_period_us: float
    clocks: dict = field(default_factory=dict)  # per stream: how its stamps were regularised

    @property
    def name(self) -> str:
        return f"{self.hq}->{self.lq}"

    @property
    def lq_color_frames(self) -> frozenset:
        cached = self.__dict__.get("_lq_color_frames")
        if cached is None:
            cached = self.__dict__["_lq_color_frames"] = frozenset(int(f) for f in self.f_lq_c)
        return cached


def pair_setup(session: Session, *, lq: str, hq: str, dejitter: bool = True) -> PairSetup:
    """Resolve streams and calibration of the pair; one-line errors for what is missing.

    With ``dejitter`` every stream's host stamps are regularised against its frame numbers
    (``align.timestamps``); everything downstream uses those stamps.
    """
    where = session.manifest_path
    for sid in (lq, hq):
        if sid not in session.sensors:
            raise AlignError(f"{where}: no sensor {sid!r} (sensors: {', '.join(session.sensors)})")
    streams = {}
    for sid in (lq, hq):
        d = _stream_of_type(session, sid, "depth")
        c = _stream_of_type(session, sid, "color")
        if d is None:
            raise AlignError(f"{where}: sensor {sid!r} has no depth stream")
        if c is None:
            raise FeatureError(f"{where}: sensor {sid!r} has no colour stream: colour features are impossible "
                               "(record colour, or calibrate with a ChArUco board)")
        streams[sid] = (d, c)
    (lqd, lqc), (hqd, hqc) = streams[lq], streams[hq]
    stamps, clocks = {}, {}
    for sid, stream in ((lq, lqd), (hq, hqd), (lq, lqc), (hq, hqc)):
        t = session.timestamps_us(sid, stream)
        if t.size < 2:
            raise AssociationError(f"{where}: stream {sid}/{stream} has {t.size} frame(s); alignment needs at least 2")
        fn = session.frames(sid, stream)["frame_number"].to_numpy(np.int64)
        reg = regularize(fn, t) if dejitter else None
        stamps[(sid, stream)] = (fn, reg.stamps_us if reg is not None else t)
        clocks[f"{sid}/{stream}"] = reg.to_dict() if reg is not None else {"method": "raw"}
    f_lq, t_lq = stamps[(lq, lqd)]
    f_hq, t_hq = stamps[(hq, hqd)]
    f_lq_c, t_lq_c = stamps[(lq, lqc)]
    f_hq_c, t_hq_c = stamps[(hq, hqc)]
    # the HQ colour frame of each HQ depth frame: same frame number, else the nearest stamp within half a period
    period_hq = float(np.median(np.diff(t_hq)))
    pos = {int(f): i for i, f in enumerate(f_hq_c)}
    col = np.array([pos.get(int(f), -1) for f in f_hq], np.int64)
    missing = col < 0
    if missing.any():
        k = np.clip(np.searchsorted(t_hq_c, t_hq[missing]), 1, t_hq_c.size - 1)
        k = np.where(np.abs(t_hq_c[k - 1] - t_hq[missing]) <= np.abs(t_hq_c[k] - t_hq[missing]), k - 1, k)
        k = np.where(np.abs(t_hq_c[k] - t_hq[missing]) < period_hq / 2, k, -1)
        col[missing] = k

    def T_depth_color(sid: str) -> Transform:
        T = session.sensors[sid].T_depth_color
        if T is None:
            raise AlignError(f"{where}: sensor {sid!r} has colour and depth but no T_depth_color (its own calibration)")
        return T

    return PairSetup(session=session, lq=lq, hq=hq, lq_depth=lqd, lq_color=lqc, hq_depth=hqd, hq_color=hqc,
                     K_lq=session.intrinsics(lq, lqd), K_lq_color=session.intrinsics(lq, lqc),
                     K_hq=session.intrinsics(hq, hqd), K_hq_color=session.intrinsics(hq, hqc),
                     T_lqdepth_lqcolor=T_depth_color(lq), T_hqdepth_hqcolor=T_depth_color(hq),
                     t_lq=t_lq, f_lq=f_lq, t_lq_c=t_lq_c, f_lq_c=f_lq_c, t_hq=t_hq, f_hq=f_hq, t_hq_c=t_hq_c,
                     f_hq_c=f_hq_c, hq_color_of_depth=col, lq_period_us=float(np.median(np.diff(t_lq))), clocks=clocks)


# --------------------------------------------------------------------------------------- probes
@dataclass
class FeatureProbe(Probe):
    """A :class:`~align.time_shift.Probe` plus the ``patches`` of its matched HQ keypoints (in ``points``
    order) that the photometric refinement (:func:`refine_probe_tracks`) needs."""

    patches: Patches | None = None


class ProbeBuilder:
    """Reads the frames of a probe and computes its features (once per frame)."""

    def __init__(self, setup: PairSetup, opts: AlignOptions) -> None:
        self.s, self.o = setup, opts
        self.range_us = (int(-opts.shift_range_ms * 1000), int(opts.shift_range_ms * 1000))
        self.to_hq_color = DepthWarper(setup.K_hq, setup.K_hq_color, setup.T_hqdepth_hqcolor.inverse(),
                                       edge_rel=opts.edge_rel)
        self.n_matches = 0

    def candidates(self) -> np.ndarray:
        """HQ depth frames that have a colour frame and LQ colour frames around them for the whole range."""
        s = self.s
        ok = [i for i in range(s.t_hq.size)
              if s.hq_color_of_depth[i] >= 0 and probe_window(int(s.t_hq[i]), s.t_lq_c, self.range_us).size >= 2]
        return np.asarray(ok, np.int64)

    def __call__(self, i: int) -> Probe | None:
        s, o = self.s, self.o
        t = int(s.t_hq[i])
        win = probe_window(t, s.t_lq_c, self.range_us)
        if win.size < 2:
            return None
        centre = t + (self.range_us[0] + self.range_us[1]) / 2
        anchor = int(np.argmin(np.abs(s.t_lq_c[win] - centre)))
        sess = s.session
        rgb_hq = sess.read_color(s.hq, int(s.f_hq_c[s.hq_color_of_depth[i]]), stream=s.hq_color)
        d_hq = sess.read_depth(s.hq, int(s.f_hq[i]), stream=s.hq_depth)
        d_col = self.to_hq_color(d_hq)
        fh = detect(rgb_hq, kind=o.features, max_features=o.max_features, mask=np.isfinite(d_col),
                    scale=_detect_scale(rgb_hq, o.detect_scale))
        X = s.T_hqdepth_hqcolor.apply(lift(fh.xy, d_col, s.K_hq_color))
        ok = np.all(np.isfinite(X), axis=1)
        if ok.sum() < 2:
            return Probe(hq_index=i, t_hq_us=t, points=np.empty((0, 3)), lq_index=s.f_lq_c[win], t_lq_us=s.t_lq_c[win],
                         tracks=np.empty((win.size, 0, 2)), anchor=anchor)
        fh = type(fh)(fh.xy[ok], fh.descriptors[ok], fh.kind)
        X = X[ok]
        w_grad = inverse_depth_gradient(d_col, fh.xy)
        greys, rgb_anchor = [], None
        for k, j in enumerate(win):
            rgb = sess.read_color(s.lq, int(s.f_lq_c[j]), stream=s.lq_color)
            if k == anchor:
                rgb_anchor = rgb
            greys.append(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY))
        fl = detect(rgb_anchor, kind=o.features, max_features=o.max_features,
                    scale=_detect_scale(rgb_anchor, o.detect_scale))
        ia, ib = match(fh, fl)
        tracks = track(greys, anchor, fl.xy[ib])
        patches = hq_patches(rgb_hq, d_col, s.K_hq_color, fh.xy[ia], sigma_px=PATCH_BLUR_PX * max(
            1.0, s.K_hq_color.fx / s.K_lq_color.fx), edge_rel=o.edge_rel) if o.refine_features else None
        return FeatureProbe(hq_index=i, t_hq_us=t, points=X[ia], lq_index=win, t_lq_us=s.t_lq_c[win], tracks=tracks,
                            anchor=anchor, w_grad=w_grad[ia], patches=patches)


#: Gaussian blur (px of the finer of the two colour images) before the photometric refinement; the
#: coarser image gets the same blur in angle. Chosen on seeds 1001-1003 (session 9, ``extr`` notes).
PATCH_BLUR_PX = 0.5


#: the share of the first fit's correspondences the photometric refinement must place for ``T_ex`` to be fitted
#: again on them; below it (views of a multi-view rig that see one another's texture at other scales, where
#: few patches settle: the demo's four-view rig kept 2) the first fit stands
REFINE_MIN_KEPT = 0.25


def refine_probe_tracks(setup: PairSetup, probes: list[Probe], T_lqcolor_hqdepth: Transform, shift_us: np.ndarray) -> tuple[int, int]:
    """Move each probe's LQ tracks to the photometrically refined keypoints, in place.

    Per probe, the LQ colour frame of its window nearest the HQ instant plus the fitted shift
    (``shift_us``, one per probe) is read again; every track moves by its keypoint's offset there
    (:func:`align.features.refine_offsets`, patch shapes from ``T_lqcolor_hqdepth``). The frame
    nearest the HQ instant, not the matching anchor: a moving surface looks most like the HQ patch
    there (at a 55 ms shift the anchor frame's offsets put ``T_lq_hq`` 1.5 mm off in x). Keypoints
    that cannot be refined lose their track (NaN): their SIFT positions carry the error the
    refinement removes. Probes without patches are left alone. Returns ``(refined, dropped)``.
    """
    s = setup
    T = T_lqcolor_hqdepth @ s.T_hqdepth_hqcolor
    sigma = PATCH_BLUR_PX * max(1.0, s.K_lq_color.fx / s.K_hq_color.fx)
    refined = dropped = 0
    for p, d in zip(probes, np.asarray(shift_us, np.float64).reshape(-1)):
        if getattr(p, "patches", None) is None or p.n_features == 0:
            continue
        j = int(np.argmin(np.abs(p.t_lq_us - (p.t_hq_us + d))))
        rgb = s.session.read_color(s.lq, int(s.f_lq_c[p.lq_index[j]]), stream=s.lq_color)
        off, ok = refine_offsets(p.patches, rgb, s.K_lq_color, T, p.tracks[j], sigma_px=sigma)
        p.tracks += off[None]
        p.tracks[:, ~ok] = np.nan
        refined += int(ok.sum())
        dropped += int((~ok).sum())
    return refined, dropped


#: Detection runs at full resolution when the default resize would keep more than this share of each
#: side: a slight resize saves little time, and on half-scale simulated sessions (HQ colour 480x270,
#: resized 0.889x) it biased the alignment loop's HQ lens k1 by +0.0025 on clean sessions and by
#: +0.004 more at k1 = -0.1, with a spurious 4 mm depth offset on 2 of 4 seeds (notes of issue 12).
FULL_RES_ABOVE = 0.75


def _detect_scale(image: np.ndarray, scale: float | None) -> float:
    if scale is not None:
        return float(scale)
    s = float(min(1.0, max(0.5, 240.0 / min(image.shape[:2]))))
    return 1.0 if s > FULL_RES_ABOVE else s


def _spread(n: int, k: int) -> np.ndarray:
    """``min(k, n)`` indices of ``range(n)`` spread evenly, first and last included."""
    return np.unique(np.linspace(0, n - 1, min(k, n)).round().astype(int)) if n else np.zeros(0, int)


def _run_probes(builder: ProbeBuilder, frames: np.ndarray, opts: AlignOptions, desc: str) -> list[Probe]:
    """The probes of HQ depth ``frames`` (threads: OpenCV and numpy release the GIL)."""
    threads = cv2.getNumThreads()
    if opts.workers > 1:
        cv2.setNumThreads(1)
    try:
        with ThreadPoolExecutor(max_workers=max(1, opts.workers)) as pool:
            it = pool.map(builder, frames.tolist())
            return [p for p in tqdm(it, total=frames.size, desc=f"{desc} {builder.s.name}", unit="frame",
                                    disable=not opts.progress, file=sys.stderr, leave=False) if p is not None]
    finally:
        cv2.setNumThreads(threads)


class ProbeDraw:
    """A pair's probes, drawn from its candidate frames: ``opts.probes`` spread evenly at first, then, on each
    :meth:`more`, as many again as are drawn, spread evenly over the candidates not used yet."""

    def __init__(self, setup: PairSetup, opts: AlignOptions, *, desc: str = "features") -> None:
        self.setup, self.opts, self.desc = setup, opts, desc
        self.builder = ProbeBuilder(setup, opts)
        self.candidates = self.builder.candidates()
        if self.candidates.size == 0:
            lo, hi = self.builder.range_us
            raise AssociationError(
                f"{setup.session.root}: {setup.hq}/{setup.hq_depth} ({setup.t_hq[0]}..{setup.t_hq[-1]} us) and "
                f"{setup.lq}/{setup.lq_color} ({setup.t_lq_c[0]}..{setup.t_lq_c[-1]} us) do not overlap for any shift "
                f"in [{lo / 1000:g}, {hi / 1000:g}] ms")
        self.used = _spread(self.candidates.size, opts.probes)
        self._probes = _run_probes(self.builder, self.candidates[self.used], opts, desc)

    @property
    def probes(self) -> list[Probe]:
        """The probes drawn so far, in time order."""
        return sorted(self._probes, key=lambda p: p.hq_index)

    @property
    def matches(self) -> int:
        return sum(p.n_features for p in self._probes)

    def more(self, why: str) -> bool:
        """Draw the next round (logged with ``why``); False when every candidate is used."""
        rest = np.setdiff1d(np.arange(self.candidates.size), self.used)
        if rest.size == 0:
            return False
        more = rest[_spread(rest.size, self.used.size)]
        log.info("%s: %s over %d probes: %d more probe frames", self.setup.name, why, self.used.size, more.size)
        self._probes += _run_probes(self.builder, self.candidates[more], self.opts, self.desc)
        self.used = np.union1d(self.used, more)
        return True


def draw_probes(setup: PairSetup, opts: AlignOptions, *, desc: str = "features") -> ProbeDraw:
    """``opts.probes`` probes spread evenly over the session, more where their matches fall short.

    A pair whose probes hold fewer than ``opts.min_matches`` colour matches (views of a multi-view rig
    that share little texture: the demo's four-view rig had a pair at 57 of 60 with 8 probes) gets more
    probes from the rest of the session before it is refused (:meth:`ProbeDraw.more`, until the matches
    suffice or every candidate is used). A pair with enough matches at first keeps exactly its first probes.
    """
    draw = ProbeDraw(setup, opts, desc=desc)
    while draw.matches < opts.min_matches and draw.more(f"{draw.matches} colour matches (need {opts.min_matches})"):
        pass
    if draw.matches < opts.min_matches:
        raise FeatureError(f"{setup.session.root}: only {draw.matches} colour feature matches between {setup.hq} and "
                           f"{setup.lq} over {len(draw.used)} frames (need {opts.min_matches}): no common texture, "
                           "no overlap of the views, or no depth under the HQ features")
    return draw


def build_probes(setup: PairSetup, opts: AlignOptions, *, desc: str = "features") -> tuple[list[Probe], int]:
    """The probes of :func:`draw_probes` in time order, and the number of candidate frames."""
    draw = draw_probes(setup, opts, desc=desc)
    return draw.probes, int(draw.candidates.size)


# --------------------------------------------------------------------------------------- the fit
@dataclass
class PairFit:
    """What :func:`fit_pair` found (no truth involved)."""

    setup: PairSetup
    shift: ShiftEstimate
    fit: ExtrinsicFit
    T_lq_hq: Transform
    probes: list[Probe]
    feature_residuals_px: np.ndarray
    candidates: int
    seconds: float
    board: dict | None = None  # ChArUco calibration summary when T_lq_hq came from a board
    loop: object | None = None  # align.loop.run.LoopResult when the effect loop ran
    rig_std: tuple[float, float] | None = None  # (m, deg) when T_lq_hq came from the refined multi-view rig
    #: the probes with the photometrically refined LQ tracks ``fit`` was fitted on (None: not refined, or too
    #: few placed); the effect loop refits its final model on them (``align.loop.run``)
    refined_probes: list[Probe] | None = None

    def time_shift_at(self, t_hq_us) -> np.ndarray:
        return self.shift.shift_at(t_hq_us)


def _time_shift(setup: PairSetup, opts: AlignOptions, probes: list[Probe], *, declared, drift, rng) -> ShiftEstimate:
    """The time shift of ``probes`` (:func:`align.time_shift.estimate_time_shift`); where it is unobservable and
    ``opts.on_unobservable`` flags, the declared shift (or 0) with a warning."""
    try:
        return estimate_time_shift(probes, setup.K_lq_color, range_us=rng, step_us=int(opts.shift_step_ms * 1000),
                                   model=opts.time_model, drift_ppm=drift, declared_shift_us=declared,
                                   t0_us=int(setup.t_hq[0]))
    except UnobservableError as exc:
        if opts.on_unobservable == "error":
            raise
        shift = exc.estimate
        shift.time_shift_us = float(declared or 0.0)
        log.warning("%s", exc)
        return shift


def fit_pair(setup: PairSetup, opts: AlignOptions) -> PairFit:
    """Time shift and extrinsics of one pair from colour features. Never reads ``truth/``.

    The probes are :func:`draw_probes`'; where their matches, enough in number, still fit no pose (the shift's
    PnP on the static features or the joint fit stops with a :class:`FeatureError`: too few pairs whose tracks
    reach the shifted instant, or none that agree), more are drawn (:meth:`ProbeDraw.more`) and the fit repeated,
    until it fits or every candidate frame is used."""
    t_start = time.perf_counter()
    facts = setup.session.clock_facts
    declared = facts.get("time_shift_us")
    drift = facts.get("drift_ppm")
    rng = (int(-opts.shift_range_ms * 1000), int(opts.shift_range_ms * 1000))
    if declared is None and overlap_us(setup.t_hq, setup.t_lq, rng[0]) == 0 and overlap_us(setup.t_hq, setup.t_lq, rng[1]) == 0 \
            and overlap_us(setup.t_hq, setup.t_lq, 0) == 0:
        raise AssociationError(f"{setup.session.root}: {setup.hq} ({setup.t_hq[0]}..{setup.t_hq[-1]} us) and {setup.lq} "
                               f"({setup.t_lq[0]}..{setup.t_lq[-1]} us) do not overlap in time for any shift within "
                               f"+-{opts.shift_range_ms:g} ms")
    draw = draw_probes(setup, opts)
    while True:  # more probes where the matches, enough in number, still fit no pose (tracks broken at the shift)
        probes = draw.probes
        try:
            shift = _time_shift(setup, opts, probes, declared=declared, drift=drift, rng=rng)
            # T_ex over all probes jointly: Delta is settled now (found with T_ex from static features
            # only), so the moving features' interpolated positions add their information too
            loss = ShiftLoss(probes, shift.T_init, setup.K_lq_color, t0_us=shift.t0_us)
            pos, _ = loss.lq_positions(shift.time_shift_us, shift.drift_ppm * 1e-6)
            good = np.all(np.isfinite(pos), axis=1)
            fit = fit_extrinsics(loss.points[good], pos[good], setup.K_lq_color, T_init=shift.T_init,
                                 clusters=fit_clusters(setup, loss)[good])
            break
        except FeatureError as exc:
            if not draw.more(f"{exc} at {draw.matches} colour matches"):
                raise
    n_cand = int(draw.candidates.size)
    refined = None
    if opts.refine_features:  # the keypoints' own localisation error, then T_ex again
        fit, loss, refined = _refit_on_refined_keypoints(setup, probes, fit, loss, shift, n_first=int(good.sum()))
    fit = with_shift_uncertainty(fit, loss, shift)
    T_lq_hq = setup.T_lqdepth_lqcolor @ fit.T
    pf = PairFit(setup=setup, shift=shift, fit=fit, T_lq_hq=T_lq_hq, probes=probes, feature_residuals_px=fit.residuals_px,
                 candidates=n_cand, seconds=time.perf_counter() - t_start, refined_probes=refined)
    if opts.board is not None:
        pf.T_lq_hq, pf.board = calibrate_with_board(setup, opts, pf.time_shift_at)
        pf.seconds = time.perf_counter() - t_start
    return pf


#: The HQ depth image is cut into this many cells a side for the second clustering of the extrinsic fit's rows
#: (:func:`fit_clusters`; the effect loop's feature phase clusters the same way, ``align.loop.loop.CELLS``).
FIT_CELLS = 8


def fit_clusters(setup: PairSetup, loss: ShiftLoss) -> np.ndarray:
    """``(F, 2)`` cluster labels of the extrinsic fit's rows (:func:`align.extrinsics.cluster_covariance`): the
    probe of each feature (one frame's timing and tracking) and the cell (:data:`FIT_CELLS` a side) of the HQ depth
    image its HQ point lies in: still texture shows the same keypoints to every probe, and neighbouring keypoints'
    placement errors are alike. Chosen over the keypoints themselves (a 2 px grid) on seeds 5001-5006, where it
    covered every axis on all six; held out: seeds 6001-6016 (drawn shift) and 7001-7010 (synchronous), session
    10, ``tidy`` notes."""
    K = setup.K_hq
    uv = K.project(loss.points)
    return np.stack([loss.probe_id, grid_cells(uv[:, 0], uv[:, 1], width=K.width, height=K.height, cells=FIT_CELLS)],
                    axis=1)


def _refit_on_refined_keypoints(setup: PairSetup, probes: list[Probe], fit: ExtrinsicFit, first: ShiftLoss, shift, *,
                                n_first: int) -> tuple[ExtrinsicFit, ShiftLoss, list[Probe] | None]:
    """``T_ex`` fitted again on the photometrically refined keypoints (:func:`refine_probe_tracks`), or ``fit``
    itself when the refinement places fewer than ``REFINE_MIN_KEPT`` of the first fit's ``n_first``
    correspondences; returned with the tracks it was fitted on (``first``'s, or the refined ones) and the refined
    probes (None where the first fit stands). The probes are copied: the effect loop (align.loop) searches on the
    SIFT tracks (fed the refined ones, its residual scale halves and it accepted a lens k1 or a clock drift on 3 of
    11 clean sessions) and refits the model it chose on the refined ones."""
    refined = [replace(p, tracks=p.tracks.copy()) for p in probes]
    refine_probe_tracks(setup, refined, fit.T, shift.shift_at(np.array([p.t_hq_us for p in refined])))
    try:
        loss = ShiftLoss(refined, fit.T, setup.K_lq_color, t0_us=shift.t0_us)
        pos, _ = loss.lq_positions(shift.time_shift_us, shift.drift_ppm * 1e-6)
        kept = np.all(np.isfinite(pos), axis=1)
    except UnobservableError:   # no refined track through a whole window
        kept = np.zeros(0, bool)
    if kept.sum() >= max(MIN_POINTS, REFINE_MIN_KEPT * n_first):
        return fit_extrinsics(loss.points[kept], pos[kept], setup.K_lq_color, T_init=fit.T,
                              clusters=fit_clusters(setup, loss)[kept]), loss, refined
    log.warning("%s: the feature refinement placed only %d of %d keypoints; T_ex stays the fit of the keypoints as "
                "detected", setup.session.root, int(kept.sum()), n_first)
    return fit, first, None


#: the step of the central difference that carries the time shift's uncertainty into ``T_ex``'s (us)
SHIFT_STEP_US = 500.0


def shift_sensitivity(loss: ShiftLoss, fit: ExtrinsicFit, shift: ShiftEstimate) -> np.ndarray:
    """``(6,)``: d(rotation vector rad, translation m) of the fitted ``T_ex`` per microsecond of the time shift.

    ``T_ex`` is fitted at the found shift; the moving features' LQ positions are interpolated along their tracks
    at that instant, so an error of the shift moves them along their motion (people walk sideways: 1-1.4 mm of
    ``t_x`` per ms on simulated people sessions). Central difference: the same rows refitted at the shift
    +- :data:`SHIFT_STEP_US`. NaN when a refit fails.
    """
    drift = shift.drift_ppm * 1e-6
    pos = [loss.lq_positions(shift.time_shift_us + d, drift)[0] for d in (SHIFT_STEP_US, -SHIFT_STEP_US)]
    ok = np.all(np.isfinite(pos[0]), axis=1) & np.all(np.isfinite(pos[1]), axis=1)
    try:
        T = [fit_extrinsics(loss.points[ok], p[ok], loss.K, T_init=fit.T).T for p in pos]
    except FeatureError:
        return np.full(6, np.nan)
    return (np.concatenate([T[0].rotvec(), T[0].t]) - np.concatenate([T[1].rotvec(), T[1].t])) / (2 * SHIFT_STEP_US)


def with_shift_uncertainty(fit: ExtrinsicFit, loss: ShiftLoss, shift: ShiftEstimate) -> ExtrinsicFit:
    """``fit`` with the time shift's variance carried into its covariance: ``cov + g g^T sd_shift^2``
    (:func:`shift_sensitivity`); the pose is unchanged. Left as it is where the shift is unobservable (its value a
    placeholder, its error unknown) or has no finite sd."""
    if not (shift.observable and np.isfinite(shift.std_us) and shift.std_us > 0):
        return fit
    g = shift_sensitivity(loss, fit, shift)
    if not np.all(np.isfinite(g)):
        return fit
    return replace(fit, covariance=fit.covariance + np.outer(g, g) * shift.std_us ** 2,
                   covariance_fit=fit.covariance)


def calibrate_with_board(setup: PairSetup, opts: AlignOptions, shift_at) -> tuple[Transform, dict]:
    """T_lq_hq from a recorded ChArUco board (``align.charuco``): the board's pose in the HQ and the
    LQ colour images of up to ``opts.board_frames`` pairs (paired at the fitted shift), combined
    robustly; ``T_lq_hq = T_lqdepth_lqcolor * T_lqcolor_hqcolor * T_hqcolor_hqdepth``."""
    from align.charuco import BoardSpec, board_pose, detect_board, extrinsics_from_boards
    from align.errors import CalibrationBoardError

    spec = BoardSpec.parse(opts.board)
    sess = setup.session
    idx = np.unique(np.linspace(0, setup.t_hq_c.size - 1, min(opts.board_frames, setup.t_hq_c.size)).round().astype(int))
    lq_of = nearest_mapping(setup.t_hq_c[idx], setup.t_lq_c, shift_at(setup.t_hq_c[idx]))
    poses_hq, poses_lq = [], []
    for i, j in zip(idx, lq_of):
        try:
            a = board_pose(*detect_board(sess.read_color(setup.hq, int(setup.f_hq_c[i]), stream=setup.hq_color), spec),
                           spec, setup.K_hq_color)
            b = board_pose(*detect_board(sess.read_color(setup.lq, int(setup.f_lq_c[j]), stream=setup.lq_color), spec),
                           spec, setup.K_lq_color)
        except CalibrationBoardError:
            continue
        poses_hq.append(a.T_cam_board)
        poses_lq.append(b.T_cam_board)
    if not poses_hq:
        raise CalibrationBoardError(f"{sess.root}: the ChArUco board {opts.board} was not seen by both {setup.hq} and "
                                    f"{setup.lq} in any of {idx.size} frame pairs")
    T_lqc_hqc, spread = extrinsics_from_boards(poses_lq, poses_hq)
    T = setup.T_lqdepth_lqcolor @ T_lqc_hqc @ setup.T_hqdepth_hqcolor.inverse()
    return T, {"board": opts.board, **spread}


# --------------------------------------------------------------------------------------- pairs
@dataclass
class PairTable:
    """Every candidate pair, kept or not, and why (``pairs.csv``)."""

    hq_index: np.ndarray
    lq_index: np.ndarray
    dt_us: np.ndarray
    residual: np.ndarray
    reason: list[str]

    @property
    def kept(self) -> np.ndarray:
        return np.array([r == "" for r in self.reason], bool)

    def counts(self) -> dict:
        out: dict[str, int] = {}
        for r in self.reason:
            if r:
                out[r] = out.get(r, 0) + 1
        return out

    def to_csv(self, setup: PairSetup, shift_us: np.ndarray) -> str:
        lines = ["hq_frame,lq_frame,t_hq_us,t_lq_us,shift_us,dt_us,depth_residual_rel,kept,reason"]
        for k in range(self.hq_index.size):
            i, j = int(self.hq_index[k]), int(self.lq_index[k])
            res = "" if not np.isfinite(self.residual[k]) else f"{self.residual[k]:.6f}"
            lines.append(f"{setup.f_hq[i]},{setup.f_lq[j] if j >= 0 else ''},{setup.t_hq[i]},"
                         f"{setup.t_lq[j] if j >= 0 else ''},{shift_us[k]:.1f},{self.dt_us[k] if j >= 0 else ''},{res},"
                         f"{int(self.reason[k] == '')},{self.reason[k]}")
        return "\n".join(lines) + "\n"


def pair_frames(setup: PairSetup, pf: PairFit, opts: AlignOptions) -> PairTable:
    """Eq. 28 (or greedy) at the fitted shift; reasons for the pairs dropped on time."""
    shift = pf.time_shift_at(setup.t_hq)
    max_dt = int((opts.max_dt_ms * 1000) if opts.max_dt_ms is not None else setup.lq_period_us / 2)
    a = associate(setup.t_hq, setup.t_lq, time_shift_us=shift, method=opts.association, max_difference_us=max_dt + 1,
                  hq_name=f"{setup.hq}/{setup.hq_depth}", lq_name=f"{setup.lq}/{setup.lq_depth}")
    lq_of = np.full(setup.t_hq.size, -1, np.int64)
    dt = np.zeros(setup.t_hq.size, np.int64)
    lq_of[a.hq_index], dt[a.hq_index] = a.lq_index, a.dt_us
    reason = ["" if lq_of[i] >= 0 else f"no LQ frame within {max_dt / 1000:g} ms" for i in range(setup.t_hq.size)]
    dup = set() if pf.loop is None else set(int(j) for j in pf.loop.lq_duplicates)
    for i in np.flatnonzero(np.isin(lq_of, list(dup))) if dup else ():
        reason[i] = "LQ frame duplicates its predecessor (its content is of an earlier instant)"
    # eq. 28 may give one LQ frame to two HQ frames: keep the nearer in time
    best: dict[int, int] = {}
    for i in np.flatnonzero(lq_of >= 0):
        j = int(lq_of[i])
        if j in best:
            other = best[j]
            loser = i if abs(dt[i]) >= abs(dt[other]) else other
            reason[loser] = "LQ frame already paired with a nearer HQ frame"
            best[j] = other if loser == i else i
        else:
            best[j] = int(i)
    return PairTable(hq_index=np.arange(setup.t_hq.size), lq_index=lq_of, dt_us=dt,
                     residual=np.full(setup.t_hq.size, np.nan), reason=reason)


# --------------------------------------------------------------------------------------- truth
class TruthSource:
    """The LQ sensor's noise-free depth of a simulated session (``truth/``), for the benchmark only.

    Created by :func:`align_session` *after* the fit is complete; the fit never sees it.
    """

    def __init__(self, session_root: Path, sensor: str) -> None:
        from capture.truth import read_truth

        self.truth = read_truth(session_root)
        self.sensor = sensor

    @staticmethod
    def available(session_root: Path) -> bool:
        return (Path(session_root) / "truth" / "truth.json").is_file()

    def depth(self, frame_number: int) -> np.ndarray:
        return self.truth.depth(self.sensor, frame_number)


# --------------------------------------------------------------------------------------- writing
@dataclass
class PairOutput:
    """What was written for one pair."""

    root: Path
    table: PairTable
    depth_residuals: dict
    report: Path | None
    kept: int
    example: dict = field(default_factory=dict)
    background: np.ndarray | None = None  # the ROI's background model (H, W) float32 metres the references used


def write_pair_dataset(root: Path, setup: PairSetup, pf: PairFit, opts: AlignOptions, *, force: bool,
                       truth: TruthSource | None, meta_extra: dict | None = None) -> PairOutput:
    """Warp, mask, filter and write one pair's aligned dataset (plus report) to ``root``."""
    sess = setup.session
    reference = pair_references(setup, T_lq_hq=pf.T_lq_hq, options=reference_options(opts))
    rule = reference.rule
    table = pair_frames(setup, pf, opts)
    lq_color_T = setup.T_lqdepth_lqcolor.inverse()
    color_registered = setup.T_lqdepth_lqcolor.is_close(Transform.identity(), 1e-9) and setup.K_lq_color == setup.K_lq
    timed = np.flatnonzero(np.array([r == "" for r in table.reason]))
    # pass 1: depth residual of every pair, and a sample of references for the background model
    sample = set(timed[np.unique(np.linspace(0, max(timed.size - 1, 0), min(opts.roi_frames, timed.size)).round()
                               .astype(int))].tolist()) if timed.size else set()
    refs = []
    for k in tqdm(timed, desc=f"residuals {setup.name}", unit="pair", disable=not opts.progress, file=sys.stderr,
                  leave=False):
        i, j = int(table.hq_index[k]), int(table.lq_index[k])
        ref = reference(i, float(table.dt_us[k])).depth
        lq = _lq_depth(sess, setup, pf, j)
        table.residual[k], n = depth_residual(lq, ref)
        if n < 100:
            table.reason[k] = "too few pixels with both depths"
        if k in sample:
            refs.append(np.where(np.isfinite(ref), ref, lq))
    bad = outliers(table.residual[timed], k=opts.residual_k, floor=0.01) if timed.size else np.zeros(0, bool)
    for k, b in zip(timed, bad):
        if b and table.reason[k] == "":
            table.reason[k] = f"depth residual above median + {opts.residual_k:g} sigma"
    kept = np.flatnonzero(table.kept)
    if kept.size == 0:
        raise AlignError(f"{sess.root}: every frame pair was dropped ({table.counts()}); nothing to write")
    background = background_depth(np.stack(refs)) if refs else None
    if rule.scored_only:  # the rule masks only what the ROI scores: the references again, knowing its background
        reference = pair_references(setup, T_lq_hq=pf.T_lq_hq, options=reference_options(opts), background=background)
    shift_all = pf.time_shift_at(setup.t_hq)
    meta = _metadata(setup, pf, table, opts, meta_extra)
    writer = AlignedDatasetWriter(root, meta, force=force, depth_unit_m=1e-4)
    example: dict = {}
    masked = np.zeros(2, np.int64)  # ROI pixels masked by the edge rule, ROI pixels
    motions: list = []
    try:
        mid = kept[kept.size // 2]
        for k in tqdm(kept, desc=f"write {setup.name}", unit="frame", disable=not opts.progress, file=sys.stderr,
                      leave=False):
            i, j = int(table.hq_index[k]), int(table.lq_index[k])
            fl = int(setup.f_lq[j])
            r = reference(i, float(table.dt_us[k]))
            ref, pm, edge_mask = r.depth, r.motion, r.edge_mask
            lq = _lq_depth(sess, setup, pf, j)
            color = _lq_color(sess, setup, fl, lq, color_registered, lq_color_T)
            ref, edge_mask = _colour_masked(rule, ref, edge_mask, color if color_registered else None, background)
            roi = foreground_mask(np.where(np.isfinite(ref), ref, lq), background) if background is not None else None
            if roi is not None:
                masked += (int((edge_mask & roi).sum()), int(roi.sum()))
            tr = truth.depth(fl) if truth is not None else None
            writer.add_frame(lq, ref, lq_color=color, roi=roi, truth=tr, lq_frame=fl, hq_frame=int(setup.f_hq[i]),
                             lq_timestamp_us=int(setup.t_lq[j]))
            motions.append((fl, pm, *_roi_counts(roi, ref, pm.masked_map)))
            if k == mid:
                example = {"lq": lq, "ref": ref, "color": color, "roi": roi, "lq_frame": fl, "hq_frame": int(setup.f_hq[i])}
        meta["reference_edges"] = {**rule.to_dict(), "masked_roi_pixels": int(masked[0]), "roi_pixels": int(masked[1])}
        writer.write_table("pairs.csv", table.to_csv(setup, shift_all))
        meta["motion"] = {**motion_summary(motions, enabled=opts.motion, min_dt_ms=opts.motion_min_dt_ms),
                          "motion_model": opts.motion_model}
        report = None
        if opts.report:
            from align.report import write_report

            report = write_report(writer.root, setup, pf, table, example, meta, truth=truth, background=background)
        writer.meta.update(meta)
        writer.close()
    except BaseException:
        writer.abort()
        raise
    if report is not None:
        report = Path(root) / "report.md"
    return PairOutput(root=Path(root), table=table, depth_residuals=meta["residuals"]["depth"], report=report,
                      kept=int(kept.size), example=example, background=background)


def reference_options(opts: AlignOptions) -> ReferenceOptions:
    """The options of :mod:`align.pair_reference` that ``opts`` sets."""
    return ReferenceOptions(reference_edges=opts.reference_edges, edge_rel=opts.edge_rel, motion=opts.motion,
                            motion_min_dt_ms=opts.motion_min_dt_ms, motion_model=opts.motion_model)


def pair_references(setup: PairSetup, *, T_lq_hq: Transform, K_lq=None, options: ReferenceOptions | None = None,
                    background: np.ndarray | None = None) -> PairReferences:
    """The pairs' references as the aligned dataset has them (:class:`align.pair_reference.PairReferences`:
    the warp, carried to the LQ instant, the edge rule), HQ frames read from the session. ``K_lq``:
    ``None``: ``setup.K_lq``; ``background``: the ROI's, for the rules that mask only what it scores."""
    sess = setup.session

    def read_hq(i: int) -> np.ndarray:
        return sess.read_depth(setup.hq, int(setup.f_hq[i]), stream=setup.hq_depth)

    def read_hq_color(i: int) -> np.ndarray | None:
        c = int(setup.hq_color_of_depth[i])
        return None if c < 0 else sess.read_color(setup.hq, int(setup.f_hq_c[c]), stream=setup.hq_color)

    return PairReferences(read_hq, K_hq=setup.K_hq, K_lq=setup.K_lq if K_lq is None else K_lq, T_lq_hq=T_lq_hq,
                          t_hq_us=setup.t_hq, options=options, background=background,
                          hq_color=(read_hq_color, setup.K_hq_color, setup.T_hqdepth_hqcolor.inverse()))


def _colour_masked(rule: EdgeRule, ref: np.ndarray, edge_mask, color, background):
    """The reference and the edge rule's mask after the LQ colour's (:meth:`EdgeRule.colour_mask`; unchanged for
    a rule without it or without a co-registered LQ colour)."""
    cm = rule.colour_mask(ref, color, background=background)
    if not cm.any():
        return ref, edge_mask
    mask = cm if edge_mask is None else (edge_mask | cm)
    return np.where(cm, np.float32(np.nan), ref).astype(np.float32, copy=False), mask


def _roi_counts(roi, ref: np.ndarray, masked) -> tuple[int | None, int | None]:
    """Reference pixels with depth, and masked by the motion compensation, inside the ROI."""
    if roi is None:
        return None, None
    return int((roi & np.isfinite(ref)).sum()), 0 if masked is None else int((roi & masked).sum())


def _lq_depth(sess, setup: PairSetup, pf: PairFit, j: int) -> np.ndarray:
    lq = sess.read_depth(setup.lq, int(setup.f_lq[j]), stream=setup.lq_depth)
    return lq if pf.loop is None else pf.loop.correct_lq_depth(lq)


def _lq_color(sess, setup: PairSetup, frame: int, lq_depth, registered: bool, T_color_depth: Transform):
    if frame not in setup.lq_color_frames:
        return None
    rgb = sess.read_color(setup.lq, frame, stream=setup.lq_color)
    if registered:
        return rgb
    return register_color(rgb, lq_depth, setup.K_lq, setup.K_lq_color, T_color_depth)


def _T_lq_hq_std(pf: PairFit) -> dict:
    """The deviation of the ``T_lq_hq`` that ``aligned.json`` reports: the rig's where the multi-view rig refinement
    set it, the effect loop's where the loop replaced it (its final fit's covariance with the time shift's shared
    error, ``align.loop.loop.FeatureLoop.covariance``), else the feature fit's."""
    if pf.rig_std is not None:
        t, r = pf.rig_std
    elif pf.loop is not None and pf.loop.changed_geometry:
        t, r = pose_std(pf.loop.features.covariance)
    else:
        t, r = pf.fit.translation_std_m, pf.fit.rotation_std_deg
    return {"rotation_deg": r, "translation_mm": 1e3 * t}


def _metadata(setup: PairSetup, pf: PairFit, table: PairTable, opts: AlignOptions, extra: dict | None) -> dict:
    sess = setup.session
    kept = table.kept
    res = table.residual[kept]
    fr = pf.fit.residuals_px
    dt_kept = table.dt_us[kept]
    meta = {
        "name": f"{sess.name}.{setup.lq}" if extra and extra.get("multiview") else sess.name,
        "sequence": sess.name,
        "source_session": {"path": str(sess.root.resolve()), "name": sess.name,
                           "frames_sha256": sess.manifest.get("checksums", {})},
        "lq_sensor": setup.lq, "hq_sensor": setup.hq,
        "lq_intrinsics": setup.K_lq.to_dict(), "hq_intrinsics": setup.K_hq.to_dict(),
        "time_shift_us": int(round(pf.shift.time_shift_us)),
        "time_model": pf.shift.to_dict(),
        "T_lq_hq": pf.T_lq_hq.to_list(),
        "T_lq_hq_std": _T_lq_hq_std(pf),
        "T_lq_hq_source": "charuco" if pf.board else "features" if pf.rig_std is None else "rig refinement",
        **({"charuco": pf.board} if pf.board else {}),
        "residuals": {
            "features": {**robust_summary(fr[np.isfinite(fr)]), "inliers": pf.fit.n_inliers, "pairs": pf.fit.n_pairs,
                         "unit": "px", "rms_inliers_px": pf.fit.rms_px},
            "depth": {**robust_summary(res), "unit": "relative |D_LQ - D_ref| / D_ref, per-pair median"},
            "time": {**robust_summary(np.abs(dt_kept)), "unit": "us, |t_LQ - (t_HQ + Delta)| of kept pairs"},
            "pairs": {"candidates": int(table.hq_index.size), "kept": int(kept.sum()), "dropped": table.counts()},
        },
        "effects": [] if pf.loop is None else pf.loop.effects_json(),
        **({} if pf.loop is None else {"loop": pf.loop.summary_json()}),
        "alignment": {"program": "depthbench align", "options": {k: v for k, v in opts.__dict__.items()},
                      "probes": len(pf.probes), "probe_candidates": pf.candidates, "fit_seconds": pf.seconds},
    }
    if extra:
        meta.update({k: v for k, v in extra.items() if k != "multiview"})
    return json.loads(json.dumps(meta, default=_json_default))


def _json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(type(o))


# --------------------------------------------------------------------------------------- entry point
@dataclass
class AlignmentResult:
    """What :func:`align_session` produced.

    ``time_shift_us`` and ``T_lq_hq`` are those of the (first) LQ sensor; for multi-view rigs
    ``views`` holds each view's fit and ``rig`` the calibrated rig. ``background``: the ROI's background model
    ``(H, W)`` float32 metres the (single pair's) references were built with (:mod:`align.roi`).
    """

    out: Path
    time_shift_us: int
    T_lq_hq: Transform
    shift: ShiftEstimate
    fit: ExtrinsicFit
    kept: int
    dropped: dict
    report: Path | None
    views: dict[str, PairFit] = field(default_factory=dict)
    rig: RigCalibration | None = None
    seconds: float = 0.0
    background: np.ndarray | None = None

    @property
    def observable(self) -> bool:
        return self.shift.observable


def align_session(session, out, *, force: bool = False, lq: str | None = None, hq: str | None = None,
                  **options) -> AlignmentResult:
    """Align a session folder (or an open :class:`Session`) and write the aligned dataset to ``out``.

    Keyword options are those of :class:`AlignOptions`. ``lq``/``hq`` pick sensors (default: the
    roles ``lq`` and ``hq``; multi-view rigs are detected from the ``view`` role).
    """
    t0 = time.perf_counter()
    opts = AlignOptions(**options)
    opts.check()
    sess = session if isinstance(session, Session) else open_session(session)
    sess.check_frame_files()   # every frame file present and readable before the long work
    out = Path(out)
    from depthbench.fsutil import check_output_free

    check_output_free(out, force=force, what="aligned dataset")
    views = sess.sensors_with_role("view")
    if views and lq is None:
        return _align_multiview(sess, out, views, opts, force=force, t0=t0)
    lq = lq or _only(sess, "lq")
    hq = hq or _only(sess, "hq")
    setup = pair_setup(sess, lq=lq, hq=hq, dejitter=opts.dejitter)
    pf = fit_pair(setup, opts)
    if opts.loop:
        from align.loop.run import close_loop

        close_loop(setup, pf, correct_depth=opts.loop_correct_depth).apply(pf)
    truth = TruthSource(sess.root, lq) if opts.attach_truth and TruthSource.available(sess.root) else None
    po = write_pair_dataset(out, setup, pf, opts, force=force, truth=truth)
    return AlignmentResult(out=out, time_shift_us=int(round(pf.shift.time_shift_us)), T_lq_hq=pf.T_lq_hq,
                           shift=pf.shift, fit=pf.fit, kept=po.kept, dropped=po.table.counts(), report=po.report,
                           views={lq: pf}, rig=None, seconds=time.perf_counter() - t0,
                           background=po.background)


#: depth frames per sensor the rig refinement reads (evenly spread over the session)
RIG_FRAMES = 40


class DepthReader:
    """A session's depth frames, each read once: the rig refinement and the view sync of a multi-view
    rig read many of the same frames (a one-second rig: every frame of every sensor, both)."""

    def __init__(self, sess: Session) -> None:
        self.sess = sess
        self.cache: dict[tuple[str, int], np.ndarray] = {}

    def __call__(self, sensor: str, stream: str, numbers) -> np.ndarray:
        """The frames ``numbers`` of ``sensor``'s depth ``stream``, stacked ``(n, H, W)``."""
        for f in numbers:
            if (sensor, int(f)) not in self.cache:
                self.cache[(sensor, int(f))] = self.sess.read_depth(sensor, int(f), stream=stream)
        return np.stack([self.cache[(sensor, int(f))] for f in numbers])


def refine_multiview_rig(sess: Session, fits: dict[str, PairFit], rig: RigCalibration, *,
                         progress: bool = True, depth: DepthReader | None = None) -> RigCalibration:
    """The feature rig refined from every sensor's static depth (:mod:`align.rig_refine`); the
    feature fits go in as the check (their own covariances). ``depth``: frames already read (shared
    with :func:`sync_multiview_views`). Never reads ``truth/``."""
    from align.rig_refine import feature_edge, refine_rig, static_cloud

    depth = depth or DepthReader(sess)
    clouds = {}
    for s in tqdm(list(rig.T_rig_sensor), desc="rig depth", unit="sensor", disable=not progress, file=sys.stderr,
                  leave=False):
        stream = _stream_of_type(sess, s, "depth")
        fn = sess.frames(s, stream)["frame_number"].to_numpy()
        pick = fn[np.unique(np.linspace(0, fn.size - 1, min(RIG_FRAMES, fn.size)).round().astype(int))]
        clouds[s] = static_cloud(depth(s, stream, pick), sess.intrinsics(s, stream))
    edges = []
    for pf in fits.values():
        st = pf.setup

        def T_of_x(x, st=st):
            return (st.T_lqdepth_lqcolor @ Transform.from_rotvec(x[:3], x[3:])).inverse()

        edges.append(feature_edge(st.hq, st.lq, pf.T_lq_hq.inverse(), T_of_x, np.concatenate([pf.fit.T.rotvec(), pf.fit.T.t]),
                                  pf.fit.covariance, n=pf.fit.n_inliers, rms_px=pf.fit.rms_px))
    r = refine_rig(rig.reference, rig.T_rig_sensor, clouds, feature_edges=edges)
    for w in r.warnings:
        log.warning("rig of %s: %s", sess.name, w)
    std = {s: (r.translation_std_m(s), r.rotation_std_deg(s)) for s in r.T_rig_sensor}
    return RigCalibration(rig.reference, r.T_rig_sensor, std=std, refinement=r.summary(),
                          T_rig_sensor_features=dict(rig.T_rig_sensor))


def sync_multiview_views(sess: Session, fits: dict[str, PairFit], rig: RigCalibration, opts: AlignOptions, *,
                         depth: DepthReader | None = None) -> dict:
    """Each view's time shift against the rig's reference from depth (:mod:`align.view_sync`), for
    the views ``opts.view_sync`` selects; an observable result replaces the fit's shift (``kind``
    ``depth`` in aligned.json), and the reference view's own pair (fitted against another view)
    takes minus that view's. ``depth``: frames already read (shared with :func:`refine_multiview_rig`).
    Returns ``{view: ViewSync}``. Never reads ``truth/``."""
    from align.view_sync import DepthFrames, frames_to_read, sync_view

    range_us = int(opts.shift_range_ms * 1000)
    frames = depth or DepthReader(sess)
    syncs = {}
    todo = [v for v, pf in fits.items() if pf.setup.hq == rig.reference
            and (opts.view_sync == "always" or not pf.shift.observable)]
    for v in tqdm(todo, desc="view sync", unit="view", disable=not opts.progress, file=sys.stderr, leave=False):
        st = fits[v].setup
        ir, iv = frames_to_read(st.t_hq, st.t_lq, range_us=range_us)
        if ir.size == 0:
            log.warning("%s: %s overlaps the reference too little in time to find its shift from depth", sess.name, v)
            continue
        ref = DepthFrames(frames(st.hq, st.hq_depth, st.f_hq[ir]), st.t_hq[ir], st.K_hq)
        view = DepthFrames(frames(st.lq, st.lq_depth, st.f_lq[iv]), st.t_lq[iv], st.K_lq)
        syncs[v] = y = sync_view(ref, view, rig.T_dst_src(rig.reference, v), range_us=range_us)
        if not y.observable:
            log.warning("%s: the time shift of %s is not observable from depth either: %s", sess.name, v, y.reason)
            continue
        fits[v].shift = _depth_shift(fits[v].shift, y.time_shift_us, y.std_us)
    for v, pf in fits.items():   # the reference view, fitted against another view
        other = pf.setup.hq
        if other != rig.reference and other in syncs and syncs[other].observable and \
                (opts.view_sync == "always" or not pf.shift.observable):
            pf.shift = _depth_shift(pf.shift, -syncs[other].time_shift_us, syncs[other].std_us)
    if opts.on_unobservable == "error":
        left = [v for v, pf in fits.items() if not pf.shift.observable]
        if left:
            raise UnobservableError(f"{sess.root}: the time shift of {', '.join(left)} is unobservable from colour "
                                    "features and from depth", estimate=fits[left[0]].shift)
    return syncs


def _depth_shift(shift: ShiftEstimate, delta_us: float, std_us: float) -> ShiftEstimate:
    was = f"; colour features: {shift.reason}" if shift.reason else ""
    return replace(shift, time_shift_us=float(delta_us), std_us=float(std_us), observable=True, model="depth",
                   drift_ppm=0.0, reason=f"from the depth of what moves, given the calibrated rig (align.view_sync){was}",
                   segments=[])


def _only(sess: Session, role: str) -> str:
    ids = sess.sensors_with_role(role)
    if not ids:
        raise AlignError(f"{sess.manifest_path}: no sensor with role {role!r} (sensors: "
                         f"{', '.join(f'{k} ({v.role})' for k, v in sess.sensors.items())})")
    return ids[0]


def _align_multiview(sess: Session, out: Path, views: list[str], opts: AlignOptions, *, force: bool,
                     t0: float) -> AlignmentResult:
    hqs = sess.sensors_with_role("hq")
    reference = hqs[0] if hqs else views[0]
    fits: dict[str, PairFit] = {}
    outputs: dict[str, PairOutput] = {}
    # an unobservable feature shift is flagged here and then found from depth (AlignOptions.view_sync)
    fit_opts = replace(opts, on_unobservable="flag") if opts.view_sync != "never" else opts
    with staged_directory(out, force=force, what="aligned multi-view dataset") as stage:
        for v in views:
            src = reference if v != reference else views[1]
            setup = pair_setup(sess, lq=v, hq=src, dejitter=opts.dejitter)
            fits[v] = fit_pair(setup, fit_opts)
        T_ref = {v: fits[v].T_lq_hq.inverse() for v in views if v != reference}
        rig = compose_rig(reference, T_ref)
        depth = DepthReader(sess)   # read once for both
        if opts.rig_refine == "always" or (opts.rig_refine == "views" and not hqs):
            rig = refine_multiview_rig(sess, fits, rig, progress=opts.progress, depth=depth)
        syncs = sync_multiview_views(sess, fits, rig, opts, depth=depth) if opts.view_sync != "never" else {}
        del depth
        if reference in fits:  # reference view fitted against another view: a loop check
            other = views[1]
            rig.loop_errors.append((reference, other, *fits[reference].T_lq_hq.error_to(rig.T_dst_src(reference, other))))
        if rig.std:
            for v, pf in fits.items():
                pf.T_lq_hq = rig.T_dst_src(v, pf.setup.hq)
                pf.rig_std = rig.std[v if v != reference else pf.setup.hq]
        atomic_write_json(stage / "rig.json", {"format": "depthbench.rig", "session": sess.name, **rig.to_dict(),
                                              "time_shift_us": {v: int(round(f.shift.time_shift_us)) for v, f in fits.items()},
                                              "time_source": {v: f.setup.hq for v, f in fits.items()},
                                              **({"time_sync": {v: y.to_dict() for v, y in syncs.items()}} if syncs else {})})
        for v in views:
            setup = fits[v].setup
            truth = TruthSource(sess.root, v) if opts.attach_truth and TruthSource.available(sess.root) else None
            outputs[v] = write_pair_dataset(stage / v, setup, fits[v], opts, force=False, truth=truth,
                                            meta_extra={"multiview": True, "rig_reference": reference})
        if opts.report:
            from align.report import write_rig_report

            write_rig_report(stage, sess, rig, fits, outputs)
    first = views[0] if views[0] != reference else views[-1]
    pf = fits[first]
    dropped = {v: o.table.counts() for v, o in outputs.items()}
    return AlignmentResult(out=out, time_shift_us=int(round(pf.shift.time_shift_us)), T_lq_hq=pf.T_lq_hq,
                           shift=pf.shift, fit=pf.fit, kept=sum(o.kept for o in outputs.values()), dropped=dropped,
                           report=out / "report.md" if opts.report else None, views=fits, rig=rig,
                           seconds=time.perf_counter() - t0)
