"""The loop inside ``align_session`` (I/O glue): reads frames, warps depth samples, runs the phases.

:func:`close_loop` takes the base fit of a pair (``align.pipeline.fit_pair``, never truth) and

1. finds duplicated frames from the frame index's image hashes and counts dropped frames
   (:mod:`align.loop.effects.frames`); duplicated LQ colour frames leave the feature tracks;
2. runs the feature phase (:func:`align.loop.loop.fit_feature_effects`) on the probes (the SIFT
   tracks: the search's thresholds are calibrated on them);
3. where it found an effect, refits the final model (pose, shift, accepted effects) on the probes'
   photometrically refined tracks (``PairFit.refined_probes``, :func:`align.loop.loop.refit_on_tracks`),
   which carry less of the keypoints' own localisation error: on the detected tracks the final
   ``T_lq_hq`` is ~1 mm off in z, as the base fit was before its own refinement (session 9's ``extr``
   notes); it falls back to the search's fit (warned) where the refinement kept too few features. Not
   where an effect was accepted with look-alikes (the data could not tell it from another, e.g. a small LQ
   lens k1 from the HQ lens's): the refined tracks' smaller noise narrows its interval while the choice
   between the two stays open (LQ k1 0.02, seeds 21-23: intervals covered 3 of 3 before this refit, 0 of 3
   with it, the estimate +8..+11 % -> +13..+18 %; ``docs/worklog/2026-11-24-s12/recheck.md``);
4. warps the HQ depth of ``depth_pairs`` pairs spread over the session with the extended
   geometry and samples pixels away from depth edges, then runs the depth phase;
5. returns a :class:`LoopResult` that :meth:`LoopResult.apply` writes into the pair's fit
   (shift and drift, ``T_lq_hq``, LQ intrinsics, pairs to leave out, LQ depth correction).

When the search adds nothing the base fit is kept as it is.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from align.association import nearest_mapping
from align.loop.effects.depth import DepthData
from align.loop.effects.frames import FrameFindings, drop_interval, duplicated
from align.loop.effects.lens import add_coeffs
from align.loop.features import pack_probes
from align.loop.loop import (DepthLoop, FeatureLoop, Finding, LoopOptions, fit_depth_effects, fit_feature_effects,
                             refit_on_tracks)
from align.loop.stratify import Signature
from align.warp import DepthWarper
from capture.camera import Intrinsics, Transform

log = logging.getLogger(__name__)

#: the share of the search's features (detected tracks) the refined tracks must keep for the final model
#: to be refitted on them (as ``align.pipeline.REFINE_MIN_KEPT`` for the base fit), and a floor
REFINED_MIN_KEPT = 0.25
REFINED_MIN_FEATURES = 30


@dataclass
class LoopResult:
    """What the loop found for one pair, and the geometry it implies."""

    features: FeatureLoop
    depth: DepthLoop | None
    frames: FrameFindings
    findings: list[Finding]
    shift_us: float
    drift_ppm: float
    T_lq_hq: Transform
    K_lq: Intrinsics
    K_lq_color: Intrinsics
    lq_duplicates: np.ndarray  # positions in the LQ depth stream
    correct_depth: bool
    seconds: dict = field(default_factory=dict)
    base: dict = field(default_factory=dict)  # the base fit's geometry: T_lq_hq, K_lq, shift_us, drift_ppm, t0_us
    refit_tracks: bool = False  # duplicated LQ colour frames were taken out of the tracks
    refined_fit: str = ""  # whether the final feature model was refitted on the refined tracks (step 3)

    @property
    def changed_geometry(self) -> bool:
        """A feature effect was found, or duplicated frames left the tracks (the base fit then used
        frames whose stamps are not their content's instant): the loop's refit replaces the base fit."""
        return any(f.phase == "features" and f.source == "found" for f in self.findings) or bool(self.refit_tracks)

    def unexplained(self) -> list[Signature]:
        """Signatures of the final model that still show structure (|z| above the threshold)."""
        sigs = list(self.features.after) + (list(self.depth.after) if self.depth else [])
        return [s for s in sigs if s.structured and s.name != "frame_interval"]

    def correct_lq_depth(self, z: np.ndarray) -> np.ndarray:
        return self.depth.correct(z) if (self.depth is not None and self.correct_depth) else z

    def effects_json(self) -> list[dict]:
        return [f.to_dict() for f in self.findings]

    def summary_json(self) -> dict:
        fl = self.features
        return {"threshold_z": fl.threshold, "scale_px": fl.scale_px, "bootstrap_replicates": int(fl.null_z.size),
                "refined_fit": self.refined_fit,
                "stages": [{"stage": s.stage, "accepted": s.accepted, "undone": s.undone,
                            "candidates": {n: c.to_dict() for n, c in s.candidates.items()}} for s in fl.stages],
                "depth_stages": [] if self.depth is None else [
                    {"stage": s.stage, "accepted": s.accepted,
                     "candidates": {n: c.to_dict() for n, c in s.candidates.items()}} for s in self.depth.stages],
                "heldout_features_px": {"before": fl.heldout_before, "after": fl.heldout_after},
                "heldout_depth_rel": None if self.depth is None else {"before": self.depth.heldout_before,
                                                                      "after": self.depth.heldout_after},
                "unexplained": [s.to_dict() for s in self.unexplained()],
                "signatures_before": [s.to_dict() for s in fl.before] + ([] if self.depth is None else
                                                                        [s.to_dict() for s in self.depth.before]),
                "signatures_after": [s.to_dict() for s in fl.after] + ([] if self.depth is None else
                                                                      [s.to_dict() for s in self.depth.after]),
                "seconds": self.seconds, "lq_depth_corrected": bool(self.correct_depth and self.depth is not None
                                                                    and any(f.phase == "depth" for f in self.findings))}

    def apply(self, pf) -> None:
        """Write the extended model into the pair's fit (``align.pipeline.PairFit``) and setup."""
        pf.loop = self
        if not self.changed_geometry:
            return
        pf.shift.time_shift_us = self.shift_us
        pf.shift.drift_ppm = self.drift_ppm
        fl = self.features
        if np.isfinite(fl.cov[6, 6]) and fl.cov[6, 6] > 0:  # cluster-robust, plus the error all probes share
            pf.shift.std_us = float(np.sqrt(fl.covariance[6, 6])) * 1000.0
        if any(f.name == "clock_drift" and f.source == "found" for f in self.findings):
            pf.shift.model = "linear (loop)"
        pf.T_lq_hq = self.T_lq_hq
        pf.setup.K_lq = self.K_lq
        pf.setup.K_lq_color = self.K_lq_color


def _co_registered(setup) -> bool:
    return (setup.T_lqdepth_lqcolor.is_close(Transform.identity(), 1e-9)
            and setup.K_lq_color.without_distortion() == setup.K_lq.without_distortion())


def frame_findings(setup) -> FrameFindings:
    """Duplicated frames (hash equal to the previous frame's) and frame-number gaps per stream."""
    sess = setup.session
    dups, dropped, expected = {}, {}, {}
    for sid, depth_s, color_s in ((setup.lq, setup.lq_depth, setup.lq_color), (setup.hq, setup.hq_depth, setup.hq_color)):
        fd, fc = sess.frames(sid, depth_s), sess.frames(sid, color_s)
        sha_c = dict(zip(fc["frame_number"].astype(int), fc["sha256"]))
        sha_d = dict(zip(fd["frame_number"].astype(int), fd["sha256"]))
        dups[f"{sid}/{depth_s}"] = duplicated(fd["frame_number"].to_numpy(np.int64), fd["sha256"].to_numpy(), sha_c)
        dups[f"{sid}/{color_s}"] = duplicated(fc["frame_number"].to_numpy(np.int64), fc["sha256"].to_numpy(), sha_d)
        for s, f in ((depth_s, fd), (color_s, fc)):
            fn = f["frame_number"].to_numpy(np.int64)
            expected[f"{sid}/{s}"] = int(fn[-1] - fn[0] + 1) if fn.size else 0
            dropped[f"{sid}/{s}"] = int(expected[f"{sid}/{s}"] - fn.size)
    return FrameFindings(dups, dropped, expected)


def _frame_effects(ff: FrameFindings, setup) -> list[Finding]:
    out = []
    n_dup = {k: int(v.size) for k, v in ff.duplicates.items() if v.size}
    if n_dup:
        total = sum(n_dup.values())
        n_all = sum(ff.expected[k] - ff.dropped[k] for k in n_dup)
        p, lo, hi = drop_interval(total, max(n_all, 1))
        out.append(Finding("duplicated_frames", "frames", {"count": float(total), "rate": p},
                           {"rate": (hi - lo) / 3.92}, {"count": "frames", "rate": "1"}, "found",
                           "frames that repeat their predecessor's image (stamp is not the content's instant); "
                           "left out of tracks and pairs", "frame_interval",
                           extra={"streams": n_dup, "rate_interval95": [lo, hi]}))
    drop = {k: v for k, v in ff.dropped.items() if v}
    if drop:
        d, e = sum(drop.values()), sum(ff.expected[k] for k in drop)
        p, lo, hi = drop_interval(d, e)
        out.append(Finding("dropped_frames", "frames", {"count": float(d), "rate": p}, {"rate": (hi - lo) / 3.92},
                           {"count": "frames", "rate": "1"}, "declared",
                           "gaps in the frame numbers; the regularised time mapping honours them", "frame_interval",
                           extra={"streams": drop, "rate_interval95": [lo, hi]}))
    return out


def depth_samples(setup, *, T_lq_hq: Transform, K_lq: Intrinsics, shift_at, pairs: int = 24, per_pair: int = 600,
                  edge_rel: float = 0.02, exclude_lq=(), seed: int = 0, correct_hq=None):
    """Sampled pixels of ``pairs`` pairs spread over the session (``DepthData``), with per pair the LQ frame
    interval before it (periods; 0 for a duplicate) and its median relative residual."""
    sess = setup.session
    lq_of = nearest_mapping(setup.t_hq, setup.t_lq, shift_at(setup.t_hq))
    dt = np.abs(setup.t_lq[lq_of] - (setup.t_hq + shift_at(setup.t_hq)))
    ok = np.flatnonzero(dt < setup.lq_period_us / 2)
    if ok.size == 0:
        return None, None, None
    pick = ok[np.unique(np.linspace(0, ok.size - 1, min(pairs, ok.size)).round().astype(int))]
    warper = DepthWarper(setup.K_hq, K_lq, T_lq_hq)
    rng = np.random.default_rng(seed)
    excl = set(int(j) for j in exclude_lq)
    cols = {k: [] for k in ("ref", "lq", "pair", "t", "xy")}
    interval, pair_res, g = [], [], 0
    kernel = np.ones((5, 5), np.uint8)
    H, W = K_lq.shape
    for i in pick:
        j = int(lq_of[i])
        ref = warper(sess.read_depth(setup.hq, int(setup.f_hq[i]), stream=setup.hq_depth))
        lq = sess.read_depth(setup.lq, int(setup.f_lq[j]), stream=setup.lq_depth)
        r = np.where(np.isfinite(ref), ref, 0).astype(np.float32)
        hi_, lo_ = cv2.dilate(r, kernel), cv2.erode(np.where(r > 0, r, 1e6).astype(np.float32), kernel)
        good = np.isfinite(ref) & np.isfinite(lq) & (ref > 0.2) & (hi_ - lo_ <= edge_rel * lo_)
        idx = np.flatnonzero(good.ravel())
        if idx.size < 100:
            continue
        gap = 0.0 if j in excl else (float(setup.t_lq[j] - setup.t_lq[j - 1]) / setup.lq_period_us if j > 0 else 1.0)
        rel = (lq.ravel()[idx] - ref.ravel()[idx]) / ref.ravel()[idx]
        interval.append(round(gap, 1))
        pair_res.append(float(np.median(np.abs(rel))))
        if j in excl:  # a duplicate's content is of another instant: in the signature, not in the fit
            continue
        sel = rng.choice(idx, size=min(per_pair, idx.size), replace=False)
        cols["ref"].append(ref.ravel()[sel].astype(np.float64))
        cols["lq"].append(lq.ravel()[sel].astype(np.float64))
        cols["pair"].append(np.full(sel.size, g))
        cols["t"].append(np.full(sel.size, float(setup.t_lq[j])))
        cols["xy"].append(np.stack([sel % W, sel // W], axis=1).astype(np.float64))
        g += 1
    if g < 4:
        return None, np.array(interval), np.array(pair_res)
    xy = np.concatenate(cols["xy"])
    rad = np.hypot((xy[:, 0] - K_lq.cx) / K_lq.fx, (xy[:, 1] - K_lq.cy) / K_lq.fy)
    d = DepthData(np.concatenate(cols["ref"]), np.concatenate(cols["lq"]), np.concatenate(cols["pair"]),
                  np.concatenate(cols["t"]), xy, rad)
    return d, np.array(interval), np.array(pair_res)


def close_loop(setup, pf, *, options: LoopOptions | None = None, correct_depth: bool = True,
               depth_pairs: int = 24, refine: bool = True) -> LoopResult:
    """Run the loop on one pair's base fit (module docstring). ``refine``: refit the final model on
    the pair's refined tracks where an effect was found (step 3). BLAS runs on one thread: the
    loop's products are thin (thousands of rows, a dozen columns), where threads only contend."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1, user_api="blas"):
        return _close_loop(setup, pf, options=options, correct_depth=correct_depth, depth_pairs=depth_pairs,
                           refine=refine)


def _refit_refined(setup, pf, fl: FeatureLoop, *, n_sift: int, skip, options: LoopOptions) -> tuple[FeatureLoop, str]:
    """``fl``'s final model refitted on the pair's refined tracks (:func:`align.loop.loop.refit_on_tracks`),
    or ``fl`` itself (with a warning) where the refinement left fewer than :data:`REFINED_MIN_KEPT` of the
    ``n_sift`` features the search used, or the refit fails its checks. Returns the model and what happened."""
    fd = pack_probes(pf.refined_probes, K_lq=setup.K_lq_color, K_hq=setup.K_hq_color,
                     T_hqcolor_hqdepth=setup.T_hqdepth_hqcolor.inverse(), t0_us=pf.shift.t0_us, skip_lq_index=skip)
    why = ""
    if len(fd) < max(REFINED_MIN_FEATURES, REFINED_MIN_KEPT * n_sift):
        why = f"the refinement kept {len(fd)} of {n_sift} features"
    else:
        out, why = refit_on_tracks(fl, fd, max_nfev=options.max_nfev, model_errors=options.model_errors)
        if out is not None:
            return out, f"refitted on {len(fd)} refined features (of {n_sift})"
    log.warning("%s: the loop's model stays its fit of the detected keypoints (%s)", setup.session.root, why)
    return fl, "fell back: " + why


def _close_loop(setup, pf, *, options: LoopOptions | None, correct_depth: bool, depth_pairs: int,
                refine: bool = True) -> LoopResult:
    o = options or LoopOptions()
    secs: dict[str, float] = {}
    t0, c0 = time.perf_counter(), time.process_time()
    ff = frame_findings(setup)
    declared = dict(setup.session.effects)
    if pf.shift.model.startswith("constant+declared") and "clock_drift_ppm" not in declared:
        declared["clock_drift_ppm"] = pf.shift.drift_ppm
    secs["frames"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    fd = pack_probes(pf.probes, K_lq=setup.K_lq_color, K_hq=setup.K_hq_color,
                     T_hqcolor_hqdepth=setup.T_hqdepth_hqcolor.inverse(), t0_us=pf.shift.t0_us,
                     skip_lq_index=ff.duplicate_positions(f"{setup.lq}/{setup.lq_color}"))
    T_base = setup.T_lqdepth_lqcolor.inverse() @ pf.T_lq_hq
    fl = fit_feature_effects(fd, T=T_base, shift_us=pf.shift.time_shift_us, declared=declared, options=o)
    secs["features"] = time.perf_counter() - t1
    dup_colour = ff.duplicate_positions(f"{setup.lq}/{setup.lq_color}")
    found = any(f.source == "found" for f in fl.findings) or dup_colour.size > 0
    alike = sorted(f.name for f in fl.findings if f.source == "found" and f.extra.get("look_alikes"))
    refined_fit = ("not run: the model is the base fit's" if not found else
                   f"not run: {', '.join(alike)} accepted with look-alikes" if alike else
                   "not run: no refined tracks" if refine else "not run: switched off")
    if found and refine and not alike and pf.refined_probes is not None:
        t1 = time.perf_counter()
        fl, refined_fit = _refit_refined(setup, pf, fl, n_sift=len(fd), skip=dup_colour, options=o)
        secs["features.refined_refit"] = time.perf_counter() - t1
    shift_us = fl.shift_us if found else pf.shift.time_shift_us
    drift = fl.drift_ppm if found else pf.shift.drift_ppm
    T_lq_hq = setup.T_lqdepth_lqcolor @ fl.T if found else pf.T_lq_hq
    delta = fl.lq_coeff_delta() if found else {}
    K_lq_color = add_coeffs(setup.K_lq_color, delta) if delta else setup.K_lq_color
    K_lq = add_coeffs(setup.K_lq, delta) if delta and _co_registered(setup) else setup.K_lq
    t0_us = pf.shift.t0_us

    def shift_at(t):
        return shift_us + drift * 1e-6 * (np.asarray(t, np.float64) - t0_us)

    t2 = time.perf_counter()
    dups = ff.duplicate_positions(f"{setup.lq}/{setup.lq_depth}")
    dd, interval, pair_res = depth_samples(setup, T_lq_hq=T_lq_hq, K_lq=K_lq, shift_at=shift_at, pairs=depth_pairs,
                                           exclude_lq=dups, seed=o.seed)
    dl = fit_depth_effects(dd, declared=declared, options=o, pair_interval=interval,
                           pair_residual=pair_res) if dd is not None else None
    secs["depth"] = time.perf_counter() - t2
    findings = list(fl.findings) + (list(dl.findings) if dl else []) + _frame_effects(ff, setup)
    secs["total"] = time.perf_counter() - t0
    secs["cpu_total"] = time.process_time() - c0  # CPU of this process: the wall time on a shared machine is not
    secs.update({f"features.{k}": v for k, v in fl.seconds.items()})
    base = {"T_lq_hq": pf.T_lq_hq, "K_lq": setup.K_lq, "shift_us": pf.shift.time_shift_us,
            "drift_ppm": pf.shift.drift_ppm, "t0_us": t0_us}
    return LoopResult(fl, dl, ff, findings, shift_us, drift, T_lq_hq, K_lq, K_lq_color, dups, correct_depth, secs, base,
                      bool(dup_colour.size), refined_fit)
