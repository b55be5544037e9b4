"""The greedy search over the effect library (issue 12, items 2-3). Pure numpy/scipy, no I/O.

Feature phase (:func:`fit_feature_effects`): every library effect is in the
:class:`~align.loop.features.FeatureModel` from the start at its neutral value; declared
effects are fixed at their declared values. The base model (pose and shift, plus what is
already accepted) is refitted non-linearly (robust Cauchy least squares), linearised (one
Jacobian column per parameter of the library), and every candidate effect (those whose
``requires`` is in the model) is compared on held-out probes (:mod:`align.loop.selection`).
Among the candidates above the threshold, with a falling BIC and a held-out improvement above
``min_improvement``, the one with the lowest BIC is accepted (:func:`choose`; look-alikes within
:data:`LOOK_ALIKE_BIC` are named with it) and the loop repeats; it stops when none is. The threshold
comes once, at the first stage, from the parametric bootstrap. The look-alikes of an accepted
effect are not candidates later (fitted together, two effects the data cannot tell apart share
the signal arbitrarily: LQ and HQ lens k1 = -0.020 and -0.041 for an LQ k1 of 0.02), and an effect
accepted with look-alikes is not refined further (no LQ k2 after an LQ k1 that may be the HQ
lens's: small HQ lenses drew a spurious LQ k2 that way). An accepted effect is refitted
non-linearly inside its physical range and taken out again (:func:`refit_check`: the stage records
why) when the refit ends at a bound, drops feature rows or does not lower the robust loss.

Depth phase (:func:`fit_depth_effects`): the same on the sampled depth pixels, with scale and
offset as candidates (linear: no re-linearisation needed).

Parameter uncertainty: a cluster-robust (sandwich) covariance, 95 % intervals at +-1.96 sigma. Depth
phase: frame pairs as clusters. Feature phase: two-way, probes and regions of the HQ image
(:func:`sandwich_two_way`: features of one probe share errors, and a static scene's points and their
keypoint errors recur in every probe). No clustering sees the time shift's error that every probe of a
session shares (:data:`align.time_shift.MODEL_ERROR_US`, which the reported shift's deviation carries); it
moves the pose too (people walk sideways: ``t_x`` 0.4-1.7 mm per ms of shift on simulated people sessions), so
:attr:`FeatureLoop.covariance` adds it to every parameter through the fit's information
(:func:`align.clustered.shared_error`; ``FeatureLoop.cov`` is the fit's own, which the findings' deviations use).
Nor does it see the pose's own session-wide error (the scene's: on simulated people sessions ``t_x`` was 1.0-1.5 mm
off, with ``r_y``, on every effect of some seeds with an accurate shift): :data:`POSE_MODEL_ERROR` adds it.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import least_squares

from align.clustered import grid_cells, shared_error, two_way_parts
from align.clustered import sandwich as clustered_sandwich
from align.loop.effects import feature_effects
from align.loop.effects.depth import DepthData, depth_effects
from align.loop.features import FeatureData, FeatureModel, interpolate_tracks
from align.loop.selection import (Comparison, HeldOut, LinearProblem, compare, folds_of, full_fit, null_threshold,
                                  rho, weights)
from align.loop.stratify import Signature, depth_signatures, feature_signatures
from align.time_shift import MODEL_ERROR_US
from capture.camera import Transform


@dataclass(frozen=True)
class LoopOptions:
    """folds/gap: held-out blocks of probes (pairs) and the groups left out on each side. alpha: false-alarm
    rate per stage of the bootstrap threshold; z_floor: the threshold's lowest value; replicates: bootstrap
    draws. min_improvement: smallest relative held-out loss drop accepted (a practical floor: on clean
    simulated sessions a lens k1 of -0.003 once passed z and BIC with a 0.12 % drop, absorbing
    structure at the HQ image border that no effect models; real effects of the issue's sizes
    drop it by 2-4 % (drift 1000 ppm over 8 s) to 30 % (lens k1 0.1); 1000 ppm over 4 s by 0.2 % or
    less, at the detection limit: :mod:`align.loop.effects.drift`). depth_min_improvement: the same
    for the depth phase (a 2 s session with LQ k1 0.1 gave a spurious 5 mm offset at 0.39 %, absorbing
    the depth error of moving edges between unsynchronised frames; a real 0.3 % scale drops it by 1.9 %,
    a 10 mm offset by 1.8 %). scale_px, depth_scale_rel:
    Cauchy scales (None: 2.5 robust sigmas of the base fit's residual). max_stages: effects accepted at most.
    model_errors: add each found effect's measured model error (``model_error`` of the feature and depth
    effects) in quadrature to its cluster-robust deviation (the fit's own is kept as ``std_fit``)."""

    folds: int = 5
    gap: int = 1
    alpha: float = 0.01
    z_floor: float = 3.0
    replicates: int = 100
    min_improvement: float = 0.0025
    depth_min_improvement: float = 0.01
    scale_px: float | None = None
    depth_scale_rel: float | None = None
    max_stages: int = 6
    max_nfev: int = 30
    seed: int = 0
    model_errors: bool = True


@dataclass
class Finding:
    """An effect in the final model: declared (applied as declared) or found by the search."""

    name: str
    phase: str  # "features", "depth" or "frames"
    params: dict
    std: dict
    units: dict
    source: str  # "declared" or "found"
    what: str
    signature: str = ""
    comparison: Comparison | None = None
    stage: int = 0
    extra: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        d = {"name": self.name, "phase": self.phase, "source": self.source, "what": self.what,
             "params": {k: float(v) for k, v in self.params.items()},
             "std": {k: (float(v) if np.isfinite(v) else None) for k, v in self.std.items()},
             "interval95": {k: [float(self.params[k] - 1.96 * self.std[k]), float(self.params[k] + 1.96 * self.std[k])]
                            for k in self.params if k in self.std and np.isfinite(self.std[k])},
             "units": dict(self.units), "signature": self.signature, "stage": self.stage}
        if self.comparison is not None:
            d.update(self.comparison.to_dict())
        d.update(self.extra)
        return d


@dataclass
class StageRecord:
    """One stage of the greedy search: every candidate's comparison and what was accepted."""

    stage: int
    candidates: dict[str, Comparison]
    accepted: str | None
    undone: str = ""  # why the accepted effect's non-linear refit was undone (:func:`refit_check`)


@dataclass
class FeatureLoop:
    """Result of :func:`fit_feature_effects`."""

    model: FeatureModel
    x: np.ndarray
    x_base: np.ndarray
    free: list[str]
    cov: np.ndarray
    findings: list[Finding]
    stages: list[StageRecord]
    threshold: float
    null_z: np.ndarray
    scale_px: float
    before: list[Signature]
    after: list[Signature]
    heldout_before: dict
    heldout_after: dict
    seconds: dict
    cov_shared: np.ndarray | None = None  # what the errors every feature shares add to ``cov`` (module docstring)

    @property
    def covariance(self) -> np.ndarray:
        """The free parameters' covariance: ``cov`` (the fit's, cluster-robust) plus ``cov_shared``."""
        return self.cov if self.cov_shared is None else self.cov + self.cov_shared

    @property
    def T(self) -> Transform:
        return self.model.pose(self.x)

    @property
    def shift_us(self) -> float:
        return float(self.x[6] * 1000.0)

    def value(self, effect: str) -> np.ndarray:
        return self.x[self.model.layout[effect]]

    @property
    def drift_ppm(self) -> float:
        return float(self.value("clock_drift")[0])

    def lq_coeff_delta(self) -> dict[str, float]:
        out = {}
        for e in self.model.effects:
            if e.name.startswith("lens_lq"):
                out.update({p: float(v) for p, v in zip(e.params, self.value(e.name))})
        return {k: v for k, v in out.items() if v}

    def accepted(self) -> list[str]:
        return [f.name for f in self.findings if f.source == "found"]


#: candidates whose BIC lies within this of the best one are look-alikes the data cannot tell apart
LOOK_ALIKE_BIC = 10.0

#: The same for the LQ and the HQ colour lens's ``k1``: a small lens on one camera is fitted nearly as
#: well by the opposite-sign lens on the other (the two cameras see the scene from nearly the same
#: place). On rendered sessions (notes of issue 12, sessions 5-6: seeds 21-23, 4 s) the wrong camera
#: won 6 of 6 at k1 = 0.02 by 1-29 BIC, the right one 6 of 6 at k1 = 0.1 by 55-115; this gap, between
#: the two, names the pair as look-alikes where the data cannot choose (held out, seeds 24-26: 5 of 5
#: small lenses within it, by 1-23).
LENS_CAMERAS_BIC = 40.0
_ALIKE_GAP = {frozenset({"lens_lq_k1", "lens_hq_k1"}): LENS_CAMERAS_BIC}


def choose(comps: dict[str, Comparison], order: list[str], *, threshold: float, min_improvement: float
           ) -> tuple[str | None, list[str]]:
    """The candidate to accept, and its look-alikes.

    Candidates must pass the held-out test (``z`` above the threshold, relative improvement above
    ``min_improvement``) and the BIC guard (it falls). Among those the lowest BIC wins; candidates
    within :data:`LOOK_ALIKE_BIC` of it (:data:`LENS_CAMERAS_BIC` for the two cameras' lens ``k1``)
    are look-alikes (reported with the finding), and among look-alikes the library's order decides
    (the LQ camera before the HQ camera).
    """
    ok = [n for n in order if comps[n].z > threshold and comps[n].delta_bic < 0 and comps[n].improvement > min_improvement]
    if not ok:
        return None, []
    win = min(ok, key=lambda n: comps[n].delta_bic)
    alike = [n for n in ok if comps[n].delta_bic <= comps[win].delta_bic
             + _ALIKE_GAP.get(frozenset({n, win}), LOOK_ALIKE_BIC)]
    best = alike[0]
    return best, [n for n in alike if n != best]


def _candidates(lib, *, fixed, accepted: list[str], dropped: list[str], ambiguous: list[str]) -> list:
    """The effects a stage compares: neither fixed (declared), accepted nor dropped (undone after its
    refit, or a look-alike of an accepted effect: the data could not tell them apart), and whose
    ``requires`` is accepted without look-alikes (an LQ k1 that may be the HQ lens's is not refined
    by an LQ k2)."""
    return [e for e in lib if e not in fixed and e.name not in accepted + dropped
            and (e.requires is None or (e.requires in accepted and e.requires not in ambiguous))]


def _cols(model: FeatureModel, effects: list[str], base: bool = True) -> np.ndarray:
    idx = list(range(7)) if base else []
    for name in effects:
        sl = model.layout[name]
        idx += list(range(sl.start, sl.stop))
    return np.asarray(idx, np.int64)


def refit(model: FeatureModel, x: np.ndarray, free: np.ndarray, *, c: float, max_nfev: int = 30) -> np.ndarray:
    """Robust non-linear least squares of the ``free`` parameters from ``x`` (Cauchy, scale ``c`` px),
    each effect parameter kept inside its physical range (:meth:`Effect.ranges`). The bounds matter:
    with ``x_scale="jac"`` a parameter of a weak column (an LQ readout on a slow scene) is given
    a trust region of hundreds of ms at the first step, where track samples leave their windows and
    the loss falls with every feature dropped; rendered seed 14 (30 ms) ran to -2458 ms this way."""
    def f(z):
        xx = x.copy()
        xx[free] = z
        return model.residuals(xx)

    def jac(z):
        xx = x.copy()
        xx[free] = z
        return model.jacobian(xx, columns=free)

    lo, hi = _ranges(model)
    lo, hi = lo[free], hi[free]
    span = np.where(np.isfinite(hi - lo), hi - lo, 1.0)
    z0 = np.clip(x[free], lo + 1e-6 * span, hi - 1e-6 * span)
    res = least_squares(f, z0, jac=jac, loss="cauchy", f_scale=c, x_scale="jac", max_nfev=max_nfev, bounds=(lo, hi))
    out = x.copy()
    out[free] = res.x
    return out


def _ranges(model: FeatureModel) -> tuple[np.ndarray, np.ndarray]:
    """``(low, high)`` ``(n_params,)``: each parameter's physical range (pose and shift unbounded)."""
    lo, hi = np.full(model.n_params, -np.inf), np.full(model.n_params, np.inf)
    for e in model.effects:
        sl = model.layout[e.name]
        lo[sl], hi[sl] = np.array(e.ranges(), float).reshape(-1, 2).T
    return lo, hi


#: An accepted effect's refit is undone when its parameter ends within this share of its range
#: from an end (the refit ran into the bound: the data want a value no device shows).
AT_BOUND = 1e-3


def refit_check(model: FeatureModel, x_prev: np.ndarray, x_new: np.ndarray, *, new_cols: np.ndarray, c: float,
                max_lost: float = 0.01) -> str:
    """Why the non-linear refit ``x_new`` (free columns ``new_cols``) of a just-accepted effect must be
    undone, or ``""``. The linearised held-out test accepted the effect; the refit must realise its
    gain: no parameter at an end of its physical range, no more than ``max_lost`` of the feature
    rows in use at ``x_prev`` leaving their windows (a feature that leaves has no residual, so the
    robust loss can fall by discarding rows), and a robust loss over those rows below ``x_prev``'s."""
    lo, hi = _ranges(model)
    tol = AT_BOUND * np.where(np.isfinite(hi - lo), hi - lo, np.inf)
    at = (x_new - lo < tol) | (hi - x_new < tol)
    names = model.names()
    if np.any(at[new_cols]):
        return "refit at the end of the physical range: " + ", ".join(
            f"{names[i]} = {x_new[i]:.4g}" for i in new_cols if at[i])
    r_a, r_b = model.residuals(x_prev), model.residuals(x_new)
    keep = r_a != 0
    lost = float(np.mean(r_b[keep] == 0)) if keep.any() else 0.0
    loss_a, loss_b = (float(np.sum(rho(r[keep], c))) / max(int(keep.sum()), 1) for r in (r_a, r_b))
    if lost > max_lost or loss_b >= loss_a:
        return (f"refit lost the gain: robust loss per row {loss_a:.4g} -> {loss_b:.4g}, "
                f"{100 * lost:.1f} % of rows left their window")
    return ""


#: The HQ colour image is cut into this many cells a side for the feature phase's second clustering.
CELLS = 8


#: The pose's error that every feature of a session shares, one sd per axis: (rotation rad, translation m), in
#: quadrature (:func:`feature_covariances`). Chosen so that error/sd has RMS 1 on the design sessions of session 11
#: (tidy2: lq-hq people 2 s with LQ lens k1 0.1 or LQ rolling shutter 30 ms, seeds 4001-4005, and 8 s with a 1000 ppm
#: drift, 4001-4004; 14 sessions): 0.005 deg and 0.26 mm. Held out (seeds 4101-4112, 35 sessions where the loop
#: replaced the pose): 95 % intervals cover r 32 / 30 / 35 and t 30 / 34 / 34 of 35 (28 / 27 / 35, 28 / 27 / 33 without).
POSE_MODEL_ERROR = (np.radians(0.005), 0.26e-3)


def feature_covariances(J: np.ndarray, r: np.ndarray, data: FeatureData, c: float) -> tuple[np.ndarray, np.ndarray]:
    """``(cov, shared)`` of the feature phase's final fit (``J`` over its free columns, pose and shift first;
    residuals ``r``, Cauchy scale ``c``): the two-way cluster-robust covariance (:func:`sandwich_two_way`, probes
    x cells of the HQ image) and what the errors every feature shares add to it: the time shift's
    (:data:`~align.time_shift.MODEL_ERROR_US`, carried into every parameter by :func:`align.clustered.shared_error`)
    and the pose's own (:data:`POSE_MODEL_ERROR`). NaN where the fit's information is singular."""
    A_inv, s = _irls_parts(J, r, c)
    if A_inv is None:
        return (np.full((J.shape[1],) * 2, np.nan),) * 2
    sd = np.zeros(J.shape[1])
    sd[6] = MODEL_ERROR_US / 1000.0  # the shift's column, in ms
    shared = shared_error(A_inv, sd)
    shared[np.arange(6), np.arange(6)] += np.repeat(np.square(POSE_MODEL_ERROR), 3)
    return _two_way(A_inv, s, np.repeat(data.probe, 2), np.repeat(_hq_cells(data), 2)), shared


def _two_way(A_inv: np.ndarray, s: np.ndarray, group_a: np.ndarray, group_b: np.ndarray) -> np.ndarray:
    Va, Vb, Vab = two_way_parts(A_inv, s, group_a, group_b)
    return Va + Vb - Vab


def sandwich_two_way(J: np.ndarray, r: np.ndarray, group_a: np.ndarray, group_b: np.ndarray, c: float) -> np.ndarray:
    """Two-way cluster-robust covariance of an IRLS fit: ``V_a + V_b - V_ab`` (Cameron, Gelbach and
    Miller 2011; :func:`align.clustered.two_way_parts`), rows correlated within a cluster of ``group_a``
    or of ``group_b`` (``(n,)`` integer labels, any order). The feature phase's rows share errors
    within a probe (one frame's pose, motion, tracking) and within a region of the HQ image: a static
    scene shows the same points to every probe, and their keypoint-location errors repeat in each
    (on rendered people sessions the k1 deviation by probe alone came out 2.5-3x too small)."""
    A_inv, s = _irls_parts(J, r, c)
    return np.full((J.shape[1],) * 2, np.nan) if A_inv is None else _two_way(A_inv, s, group_a, group_b)


def sandwich(J: np.ndarray, r: np.ndarray, group: np.ndarray, c: float) -> np.ndarray:
    """Cluster-robust covariance ``A^-1 B A^-1`` of an IRLS fit (clusters = ``group``, integer labels;
    :func:`align.clustered.sandwich`)."""
    A_inv, s = _irls_parts(J, r, c)
    return np.full((J.shape[1],) * 2, np.nan) if A_inv is None else clustered_sandwich(A_inv, s, group)


def _irls_parts(J: np.ndarray, r: np.ndarray, c: float) -> tuple[np.ndarray | None, np.ndarray]:
    """``(A^-1, scores)`` of an IRLS fit with the Cauchy weights of scale ``c``; ``A^-1`` None where singular."""
    w = weights(r, c)
    try:
        A_inv = np.linalg.inv((J * w[:, None]).T @ J)
    except np.linalg.LinAlgError:
        A_inv = None
    return A_inv, J * (w * r)[:, None]


def _heldout_summary(h: HeldOut, cols: np.ndarray) -> tuple[dict, np.ndarray]:
    p = h.p
    rows = np.zeros_like(p.r0)
    loss = h.losses(cols, rows_out=rows)
    used = p.r0 != 0
    a = np.abs(rows[used])
    return {"loss_per_row": float(loss.sum() / max(p.r0.size, 1)), "median_abs": float(np.median(a)) if a.size else 0.0,
            "rms_trimmed": float(np.sqrt(np.mean(np.sort(a)[: int(0.95 * a.size)] ** 2))) if a.size else 0.0}, loss


def _instants(model: FeatureModel, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each feature's instant in its window and the sample stamps, under parameters ``x``."""
    d = model.data
    s = np.full(len(d), x[6] * 1000.0)
    stamps = d.rel_us
    for e in model.effects:
        v = x[model.layout[e.name]]
        s = s + e.time_offset_us(d, v)
        stamps = e.sample_offset_us(d, stamps, v)
    return s, stamps


def _robust_scale(residuals: np.ndarray, *, floor: float = 0.3) -> float:
    """The Huber scale of a fit from its residuals: 2.5 robust sigmas (1.4826 MAD about 0) of the non-zero ones, at
    least ``floor``; ``floor`` where none is non-zero (as few residuals as unknowns)."""
    r = np.abs(residuals)
    r = r[r != 0]
    return float(max(floor, 2.5 * 1.4826 * np.median(r))) if r.size else floor


def fit_feature_effects(data: FeatureData, *, T: Transform, shift_us: float, declared: dict | None = None,
                        options: LoopOptions | None = None, exclude: tuple[str, ...] = ()) -> FeatureLoop:
    """The feature phase of the loop (module docstring). ``declared``: the session's ``effects``
    (e.g. ``{"clock_drift_ppm": 75}``); ``exclude``: library effects not to search."""
    o = options or LoopOptions()
    t_start = time.perf_counter()
    secs: dict[str, float] = {}
    lib = [e for e in feature_effects() if e.name not in exclude]
    if data.K_hq.has_distortion:
        lib = [e for e in lib if not e.name.startswith("lens_hq")]
    model = FeatureModel(data, lib)
    values, fixed = {}, []
    for e in lib:
        v = e.declared_values(declared or {})
        if v is not None:
            values[e.name] = v
            fixed.append(e)
    x = model.x0(T, shift_us, values)
    accepted: list[str] = []
    dropped: list[str] = []  # undone after their refit, or look-alikes of an accepted effect
    ambiguous: list[str] = []  # accepted with look-alikes
    group = np.repeat(data.probe, 2)
    folds = folds_of(data.n_probes, folds=o.folds, gap=o.gap)
    # base fit; the robust scale from its residuals
    c = o.scale_px or 1.5
    x = refit(model, x, _cols(model, []), c=c, max_nfev=o.max_nfev)
    if o.scale_px is None:
        c = _robust_scale(model.residuals(x))
    x_base = x.copy()
    secs["base_fit"] = time.perf_counter() - t_start
    stages: list[StageRecord] = []
    threshold, null_z = None, np.zeros(0)
    findings: list[Finding] = []
    before_summary = None
    for stage in range(1, o.max_stages + 1):
        t0 = time.perf_counter()
        r0, J = model.residuals(x), model.jacobian(x)
        p = LinearProblem(r0, J, group, c, model.names())
        base = _cols(model, accepted)
        cands = _candidates(lib, fixed=fixed, accepted=accepted, dropped=dropped, ambiguous=ambiguous)
        cand_cols = [_cols(model, [e.name], base=False) for e in cands]
        h = HeldOut(p, np.concatenate([base] + cand_cols), folds)
        if before_summary is None:
            before_summary, _ = _heldout_summary(h, base)
        if not cands:
            break
        if threshold is None:
            threshold, null_z = null_threshold(p, base, cand_cols, folds, replicates=o.replicates, alpha=o.alpha,
                                               z_floor=o.z_floor, seed=o.seed)
            secs["bootstrap"] = time.perf_counter() - t0
        lb = h.losses(base)
        bb = h.bic(base)
        comps = {e.name: compare(h, base, cc, base_loss=lb, base_bic=bb) for e, cc in zip(cands, cand_cols)}
        best, alike = choose(comps, [e.name for e in cands], threshold=threshold, min_improvement=o.min_improvement)
        stages.append(StageRecord(stage, comps, best))
        secs[f"stage{stage}"] = time.perf_counter() - t0
        if best is None:
            break
        x_new = refit(model, x, _cols(model, accepted + [best]), c=c, max_nfev=o.max_nfev)
        why = refit_check(model, x, x_new, new_cols=_cols(model, accepted + [best]), c=c)
        if why:
            stages[-1].undone, stages[-1].accepted = why, None
            dropped.append(best)
            continue
        x = x_new
        accepted.append(best)
        dropped += alike
        ambiguous += [best] if alike else []
        e = next(e for e in lib if e.name == best)
        findings.append(Finding(best, "features", {}, {}, dict(zip(e.params, e.units)), "found", e.what,
                                e.signature, comps[best], stage, extra={"look_alikes": alike} if alike else {}))
    t0 = time.perf_counter()
    covs, after_summary, before, after = _finalise(model, lib, fixed, findings, x, x_base, accepted, c=c, folds=folds,
                                                   model_errors=o.model_errors)
    secs.update(final=time.perf_counter() - t0, total=time.perf_counter() - t_start)
    names = model.names()
    return FeatureLoop(model, x, x_base, [names[i] for i in _cols(model, accepted)], covs[0], findings, stages,
                       float(threshold or o.z_floor), null_z, c, before, after, before_summary or {}, after_summary, secs,
                       covs[1])


def _finalise(model: FeatureModel, lib, fixed, findings: list[Finding], x, x_base, accepted, *, c: float, folds,
              model_errors: bool = True):
    """Parameters with their cluster-robust deviations (and the effect's model error, in quadrature)
    into the findings (declared ones first), the held-out error of the final model, and the
    signatures before (base fit) and after."""
    data = model.data
    group = np.repeat(data.probe, 2)
    free = _cols(model, accepted)
    r0, Jf = model.residuals(x), model.jacobian(x, columns=free)
    cov, shared = feature_covariances(Jf, r0, data, c)
    _set_params(model, lib, findings, x, cov, free, model_errors=model_errors)
    for e in fixed:
        sl = model.layout[e.name]
        findings.insert(0, Finding(e.name, "features", dict(zip(e.params, x[sl])), dict.fromkeys(e.params, 0.0),
                                   dict(zip(e.params, e.units)), "declared", e.what, e.signature))
    p = LinearProblem(r0, Jf, group, c, [model.names()[i] for i in free])
    after_summary, _ = _heldout_summary(HeldOut(p, np.arange(free.size), folds), np.arange(free.size))
    s_b, st_b = _instants(model, x_base)
    s_a, st_a = _instants(model, x)
    before = feature_signatures(data, model.residuals(x_base), shift_us=s_b, stamps=st_b)
    after = feature_signatures(data, r0, shift_us=s_a, stamps=st_a)
    return (cov, shared), after_summary, before, after


def _set_params(model: FeatureModel, lib, findings: list[Finding], x: np.ndarray, cov: np.ndarray, free: np.ndarray,
                *, model_errors: bool) -> None:
    """Each found effect's parameters at ``x`` with their deviations from ``cov`` (over the ``free``
    columns), the effect's model error added in quadrature."""
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    pos_of = {int(i): k for k, i in enumerate(free)}
    for f in findings:
        if f.source != "found":
            continue
        e = next(e for e in lib if e.name == f.name)
        idx = range(model.layout[e.name].start, model.layout[e.name].stop)
        f.params = {pname: float(x[i]) for pname, i in zip(e.params, idx)}
        f.std = {pname: float(sd[pos_of[i]]) for pname, i in zip(e.params, idx)}
        f.extra.pop("std_fit", None)
        f.extra.pop("model_error", None)
        if model_errors:
            _add_model_error(f, dict(zip(e.params, e.model_errors(model.data))))


def refit_on_tracks(fl: FeatureLoop, data: FeatureData, *, max_nfev: int = 30, model_errors: bool = True,
                    max_lost: float = 0.01) -> tuple[FeatureLoop | None, str]:
    """The final model of the feature phase ``fl`` (pose, shift and the accepted effects, jointly;
    declared effects stay at their values) fitted again, from ``fl``'s parameters, on ``data``: the
    same probes with other LQ tracks (the photometrically refined keypoints,
    ``align.pipeline.refine_probe_tracks``). The decisions stay ``fl``'s (stages, threshold,
    signatures, held-out errors: the thresholds are calibrated on the tracks the search ran on); the
    parameters, their cluster-robust covariance and the findings' values and deviations are the
    refit's. The refit's Cauchy scale is 2.5 robust sigmas of its own residuals at ``fl``'s parameters
    (the refined tracks' noise is about half the detected ones'). Returns ``(None, why)`` where the
    refit runs an effect parameter to the end of its physical range or drops more than ``max_lost`` of
    the feature rows in use at the start (:func:`refit_check`'s first two tests)."""
    model = FeatureModel(data, fl.model.effects)
    free = _cols(model, fl.accepted())
    r = model.residuals(fl.x)
    if not np.any(r != 0):
        return None, "no refined feature inside its window"
    c = _robust_scale(r, floor=0.1)
    x = refit(model, fl.x, free, c=c, max_nfev=max_nfev)
    lo, hi = _ranges(model)
    tol = AT_BOUND * np.where(np.isfinite(hi - lo), hi - lo, np.inf)
    at = ((x - lo < tol) | (hi - x < tol))[free]
    r_new = model.residuals(x)
    lost = float(np.mean(r_new[r != 0] == 0))
    if np.any(at) or lost > max_lost:
        return None, f"refit at a bound ({np.any(at)}) or {100 * lost:.1f} % of rows left their window"
    cov, shared = feature_covariances(model.jacobian(x, columns=free), r_new, data, c)
    findings = [replace(f, params=dict(f.params), std=dict(f.std), extra=dict(f.extra)) for f in fl.findings]
    _set_params(model, model.effects, findings, x, cov, free, model_errors=model_errors)
    return replace(fl, model=model, x=x, cov=cov, findings=findings, cov_shared=shared), ""


def _add_model_error(f: Finding, m: dict) -> None:
    """The effect's measured model error (``{param: value}``, 0 = none) in quadrature with the fit's
    deviation; the fit's own deviation stays as ``std_fit``."""
    if any(m.values()):
        f.extra.update({"std_fit": dict(f.std), "model_error": m})
        f.std = {k: float(np.hypot(v, m.get(k, 0.0))) for k, v in f.std.items()}


def _hq_cells(data: FeatureData) -> np.ndarray:
    """``(F,)`` the cell of the HQ colour image (``CELLS x CELLS``) each feature lies in."""
    K = data.K_hq
    return grid_cells(data.hq_xy[:, 0] + 0.5, data.hq_xy[:, 1] + 0.5, width=K.width, height=K.height, cells=CELLS)


# ----------------------------------------------------------------------------------- depth phase
@dataclass
class DepthLoop:
    """Result of :func:`fit_depth_effects`: ``scale``, ``offset_m`` of ``z_LQ = s z_HQ + o``."""

    scale: float
    offset_m: float
    findings: list[Finding]
    stages: list[StageRecord]
    threshold: float
    before: list[Signature]
    after: list[Signature]
    heldout_before: dict
    heldout_after: dict
    c: float

    def correct(self, z_lq: np.ndarray) -> np.ndarray:
        """LQ depth expressed on the HQ's scale: ``(z - o) / s``."""
        if self.scale == 1.0 and self.offset_m == 0.0:
            return z_lq
        return ((z_lq - np.float32(self.offset_m)) / np.float32(self.scale)).astype(np.float32)


def fit_depth_effects(data: DepthData, *, declared: dict | None = None, options: LoopOptions | None = None,
                      pair_interval=None, pair_residual=None) -> DepthLoop:
    """The depth phase of the loop (module docstring)."""
    o = options or LoopOptions()
    declared = declared or {}
    s_decl = float(declared.get("depth_scale", 1.0))
    o_decl = float(declared.get("depth_offset_mm", 0.0)) * 1e-3
    r0 = data.residual(s_decl, o_decl)
    c = o.depth_scale_rel or float(max(1e-3, 2.5 * 1.4826 * np.median(np.abs(r0 - np.median(r0)))))
    lib = [e for e in depth_effects() if e.declared_as not in declared]
    fixed = [e for e in depth_effects() if e.declared_as in declared]
    # the Jacobian of (s - 1, o) relative to the declared values is exact: r = r0 - ds - do / z
    J = np.stack([e.column(data) for e in lib], axis=1) if lib else np.zeros((len(data), 0))
    p = LinearProblem(r0, J, data.pair, c, [e.name for e in lib])
    folds = folds_of(p.n_groups, folds=o.folds, gap=o.gap)
    accepted: list[int] = []
    stages: list[StageRecord] = []
    findings: list[Finding] = []
    empty = np.zeros(0, np.int64)
    h = HeldOut(p, np.arange(len(lib)), folds)
    before_summary, _ = _heldout_summary(h, empty)
    threshold = None
    for stage in range(1, len(lib) + 1):
        base = np.asarray(accepted, np.int64)
        cands = [i for i in range(len(lib)) if i not in accepted]
        if not cands:
            break
        if threshold is None:
            threshold, _ = null_threshold(p, base, [np.array([i]) for i in cands], folds, replicates=o.replicates,
                                          alpha=o.alpha, z_floor=o.z_floor, seed=o.seed, parity=1)
        lb, bb = h.losses(base), h.bic(base)
        comps = {lib[i].name: compare(h, base, np.array([i]), base_loss=lb, base_bic=bb) for i in cands}
        name, alike = choose(comps, [lib[i].name for i in cands], threshold=threshold,
                             min_improvement=o.depth_min_improvement)
        stages.append(StageRecord(stage, comps, name))
        if name is None:
            break
        best = next(i for i in cands if lib[i].name == name)
        accepted.append(best)
        e = lib[best]
        findings.append(Finding(e.name, "depth", {}, {}, {e.param: e.unit}, "found", e.what, e.signature,
                                comps[e.name], stage, extra={"look_alikes": alike} if alike else {}))
    cols = np.asarray(accepted, np.int64)
    delta, r_fit = full_fit(p, cols) if cols.size else (np.zeros(0), r0)
    cov = sandwich(J[:, cols], r_fit, data.pair, c) if cols.size else np.zeros((0, 0))
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    scale, offset = s_decl, o_decl
    for k, i in enumerate(accepted):
        e = lib[i]
        f = next(f for f in findings if f.name == e.name)
        if e.param == "s_minus_1":
            scale = s_decl + delta[k]
            f.params, f.std = {"scale": scale}, {"scale": float(sd[k])}
            f.units = {"scale": "1"}
        else:
            offset = o_decl + delta[k]
            f.params, f.std = {"offset_mm": offset * 1e3}, {"offset_mm": float(sd[k]) * 1e3}
            f.units = {"offset_mm": "mm"}
        if o.model_errors:
            _add_model_error(f, {next(iter(f.params)): e.model_error * (1e3 if e.param == "o_m" else 1.0)})
    for e in fixed:
        val = {"scale": s_decl} if e.param == "s_minus_1" else {"offset_mm": o_decl * 1e3}
        findings.insert(0, Finding(e.name, "depth", val, {k: 0.0 for k in val}, {k: ("1" if k == "scale" else "mm")
                                                                                 for k in val}, "declared", e.what,
                                   e.signature))
    after_summary, _ = _heldout_summary(h, cols)
    before = depth_signatures(data, data.residual(s_decl, o_decl), pair_interval=pair_interval,
                              pair_residual=pair_residual)
    after = depth_signatures(data, data.residual(scale, offset), pair_interval=pair_interval,
                             pair_residual=pair_residual)
    return DepthLoop(float(scale), float(offset), findings, stages, float(threshold or o.z_floor), before, after,
                     before_summary, after_summary, c)


__all__ = ["DepthLoop", "FeatureLoop", "Finding", "LoopOptions", "StageRecord", "fit_depth_effects",
           "feature_covariances", "fit_feature_effects", "interpolate_tracks", "refit", "refit_on_tracks", "sandwich", "sandwich_two_way"]
