"""Time-shift search (seed report eq. 28-31): the Delta that best aligns HQ and LQ frames in space.

Pure numpy/scipy, no I/O. Convention (``truth.json``, ``aligned.json``): an instant the HQ
clock stamps ``t`` is stamped ``t + Delta`` by the LQ clock; with drift ``Delta(t) = a + b (t - t0)``.

How a candidate Delta is scored, and why the answer is sub-millisecond
--------------------------------------------------------------------
SSDD pairs each HQ frame with the LQ frame nearest to ``t_HQ + Delta`` (eq. 28) and scores
Delta with the spatial loss of those pairs (eq. 31). With 30 fps streams that loss is piecewise
constant in Delta: every Delta between two pairing switches selects the same frames, so a search
on it cannot resolve a shift finer than the ~33 ms frame spacing, however fine the grid.

Here the loss is made continuous in Delta by interpolating *in time*. Features are computed
once per frame, never per candidate:

* A *probe* is one HQ frame ``i``: its colour keypoints are matched to one LQ colour frame near
  it, lifted to 3D with the HQ depth (``align.features.lift``), and the matched LQ keypoints are
  followed by optical flow (KLT) through every LQ frame whose stamp lies in
  ``[t_i + Delta_min - T, t_i + Delta_max + T]`` (``T`` = LQ frame period). A probe therefore
  holds fixed 3D points ``X_k`` and, for each, an LQ image track ``p_k(t)`` sampled at the LQ stamps.
* For a candidate Delta, the LQ position of feature ``k`` at the HQ instant is the track
  linearly interpolated at ``tau = t_i + Delta`` between the two LQ frames around it. With
  ``T_ex`` fixed, the eq. 31 term is ``r_k(Delta) = ||pi_LQ(T_ex X_k) - p_k(t_i + Delta)||``: the
  HQ projection never changes with Delta, only where along its track the LQ point is read.
* Static features contribute a constant; moving features contribute a V-shaped term whose
  minimum sits at the true Delta with sub-frame resolution (exact for motion that is linear over
  one LQ frame interval). Only features tracked through the whole window are used, so the set
  of terms, hence the loss, is continuous in Delta everywhere in the range.
* Each term goes through a robust (Cauchy) rho so mismatches cannot dominate.

Search: a coarse scan over the whole range (default 2 ms steps) finds the basin; a bounded
Brent refinement inside the best grid cell then converges to microseconds (a bracketing
search, not a fine grid). ``T_ex`` comes from the *static* features (tracks that stay within
half a pixel over the window: their LQ position does not depend on Delta), PnP+RANSAC then
robust least squares, and the search is repeated with it; then once more with ``T_ex`` refitted
on all features at their interpolated positions (more of them: more precise, and Delta is close
by then). Starting from static features decouples the two: a large person walking close to the
cameras would otherwise tilt ``T_ex`` towards a wrong Delta, which ``T_ex`` then partly explains
away (seen on a simulated session: 7 ms and 13 mm off before, 0.6 ms and 1.9 mm after).

Uncertainty and observability: the Gauss-Newton information of Delta is ``sum_k |v_k|^2 / sigma^2``
over the moving inlier features (``v_k`` the LQ image velocity, ``sigma`` the robust residual
scale). Features of one probe share errors (a residual T_ex offset, one limb's motion), so the
reported standard deviation is the larger of that and the standard error of the per-probe
estimates (robust scatter / sqrt(probes)), with an error every probe of a session shares added
in quadrature (:data:`MODEL_ERROR_US`: the first two alone were ~2.3x optimistic on simulated
sessions). With fewer than ``min_moving`` moving features (a
feature moves when its straight-line displacement over the window exceeds ``moving_px`` and six
times its own tracking noise), or an information-based deviation above ``max_std_us``, the shift
is declared unobservable (:class:`UnobservableError`), e.g. for a static scene. A minimum on the
edge of the range raises :class:`ShiftRangeError` (checked first: a static scene is reported
as static, not as out of range).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from align.errors import AssociationError, OptionError, ShiftRangeError, UnobservableError
from align.extrinsics import fit_extrinsics
from capture.camera import Intrinsics, Transform

#: The part of the time-shift error that every probe of a session shares, µs (one sigma): no
#: within-session statistic sees it (probe scatter, a block jackknife over probes and the joint
#: pose-and-shift sandwich of :mod:`align.loop` all left RMS error/std at 2.3-3.2; the lag-1
#: correlation of one-probe estimates is ~0). Measured on simulated people sessions (2 s, scale
#: 0.5; ``perf/shift_coverage.py``, notes of issue 12): solving RMS error/std = 1 gives 285 us on
#: seeds 20-31 and 463 us on seeds 40-51 (each half's value leaves the other at 1.47 / 0.67), 383
#: us pooled; 400 us leaves 0.76 and 1.13 (95 % intervals covering 100 % and 92 %). Part of it is
#: the offset of the regularised stamps (~100 us RMS between the two streams there).
MODEL_ERROR_US = 400.0

log = logging.getLogger(__name__)

DEFAULT_RANGE_US = 60_000
DEFAULT_STEP_US = 2_000
#: a feature whose LQ track stays within this many pixels over its window is static
STATIC_PX = 0.5
#: fewest static features for T_ex to be fitted on them alone
MIN_STATIC = 40


@dataclass
class Probe:
    """One HQ frame's features with their LQ tracks around it.

    Attributes:
        hq_index: position of the HQ frame in the HQ stream. t_hq_us: its stamp.
        points: ``(N, 3)`` HQ depth-camera points of the matched keypoints, metres.
        lq_index: ``(M,)`` positions of the window's LQ frames. t_lq_us: ``(M,)`` their stamps.
        tracks: ``(M, N, 2)`` LQ colour pixels of each keypoint per window frame (NaN = lost).
        anchor: index into the window of the LQ frame the keypoints were matched in.
        w_grad: ``(N, 2)`` gradient of inverse depth at each keypoint in the HQ colour image, 1/(m px)
            (:func:`align.features.inverse_depth_gradient`), or ``None`` (taken as 0).
    """

    hq_index: int
    t_hq_us: int
    points: np.ndarray
    lq_index: np.ndarray
    t_lq_us: np.ndarray
    tracks: np.ndarray
    anchor: int
    w_grad: np.ndarray | None = None

    @property
    def n_features(self) -> int:
        return int(self.points.shape[0])


def probe_window(t_hq_us: int, t_lq_us: np.ndarray, range_us: tuple[int, int], *, margin: int = 1) -> np.ndarray:
    """Indices of the LQ frames a probe at ``t_hq_us`` needs: the frames around ``t_hq + Delta`` for
    every Delta in the range (``margin`` = 1 frame beyond each end of the range)."""
    lo = np.searchsorted(t_lq_us, t_hq_us + range_us[0], side="right") - margin
    hi = np.searchsorted(t_lq_us, t_hq_us + range_us[1], side="left") + margin - 1
    if lo < 0 or hi >= t_lq_us.size:
        return np.empty(0, np.int64)
    return np.arange(lo, hi + 1, dtype=np.int64)


def cauchy(r: np.ndarray, c: float) -> np.ndarray:
    """Robust rho(r) = c^2 log(1 + (r/c)^2): quadratic near 0, logarithmic for outliers."""
    return c * c * np.log1p((r / c) ** 2)


class ShiftLoss:
    """Eq. 31 as a continuous function of the time shift, for fixed ``T_ex``.

    Built once from the probes (features tracked through their whole window); evaluating a
    candidate costs one interpolation per feature.

    Args:
        probes: the probes. T: ``T_lqcolor_hqdepth``. K: LQ colour intrinsics.
        scale_px: Cauchy scale of the robust loss. t0_us: origin of the drift term.
    """

    def __init__(self, probes: list[Probe], T: Transform, K: Intrinsics, *, scale_px: float = 1.5,
                 t0_us: int | None = None) -> None:
        self.scale = float(scale_px)
        self.K = K
        rows_q, rows_tr, rows_ts, rows_t, rows_X, rows_pid = [], [], [], [], [], []
        M = max(p.tracks.shape[0] for p in probes)
        for pid, p in enumerate(probes):
            full = np.all(np.isfinite(p.tracks), axis=(0, 2))
            if not full.any():
                continue
            m = p.tracks.shape[0]
            tr = np.full((M, int(full.sum()), 2), np.nan)
            tr[:m] = p.tracks[:, full]
            ts = np.full(M, np.inf)
            ts[:m] = (p.t_lq_us - p.t_hq_us).astype(np.float64)  # stamps relative to the HQ stamp
            rows_tr.append(np.transpose(tr, (1, 0, 2)))
            rows_ts.append(np.broadcast_to(ts, (int(full.sum()), M)))
            rows_t.append(np.full(int(full.sum()), float(p.t_hq_us)))
            rows_X.append(p.points[full])
            rows_pid.append(np.full(int(full.sum()), pid))
        if not rows_tr:
            raise UnobservableError("no feature could be followed through a whole probe window: "
                                    "the time shift cannot be measured")
        self.tracks = np.concatenate(rows_tr)  # (F, M, 2)
        self.rel_stamps = np.ascontiguousarray(np.concatenate(rows_ts))  # (F, M) µs, inf = padding
        self.t_hq = np.concatenate(rows_t)  # (F,)
        self.points = np.concatenate(rows_X)  # (F, 3)
        self.probe_id = np.concatenate(rows_pid)
        self.t0 = float(t0_us if t0_us is not None else self.t_hq.min())
        self.motion_px, self.track_noise_px = self._motion()
        span = np.nanmax(self.tracks, axis=1) - np.nanmin(self.tracks, axis=1)
        self.static = np.linalg.norm(span, axis=1) < STATIC_PX  # (F,) their position is independent of Delta
        self.set_transform(T)
        self.evaluations = 0

    def _motion(self):
        """Per feature: the displacement along a straight-line fit to its track over the window
        (px) and the RMS of the track around that line (px, the tracking noise)."""
        t = np.where(np.isfinite(self.rel_stamps), self.rel_stamps, np.nan)
        valid = np.isfinite(t) & np.all(np.isfinite(self.tracks), axis=2)
        n = valid.sum(axis=1)
        tm = np.nansum(np.where(valid, t, 0), axis=1) / np.maximum(n, 1)
        dt = np.where(valid, t - tm[:, None], 0.0)
        p = np.where(valid[..., None], self.tracks, 0.0)
        pm = p.sum(axis=1) / np.maximum(n, 1)[:, None]
        dp = np.where(valid[..., None], p - pm[:, None, :], 0.0)
        sxx = (dt ** 2).sum(axis=1)
        slope = (dt[..., None] * dp).sum(axis=1) / np.maximum(sxx, 1e-9)[:, None]  # px/us
        resid = np.where(valid[..., None], dp - slope[:, None, :] * dt[..., None], 0.0)
        noise = np.sqrt((resid ** 2).sum(axis=(1, 2)) / np.maximum(2 * (n - 2), 1))
        span = np.where(valid, t, np.nan)
        duration = np.nanmax(span, axis=1) - np.nanmin(span, axis=1)
        return np.linalg.norm(slope, axis=1) * duration, noise

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def set_transform(self, T: Transform) -> None:
        self.T = T
        self.pred = self.K.project(T.apply(self.points))  # HQ features on the LQ image: fixed in Delta

    def shift_per_feature(self, a_us: float, b: float = 0.0) -> np.ndarray:
        return a_us + b * (self.t_hq - self.t0)

    def lq_positions(self, a_us: float, b: float = 0.0):
        """Each feature's LQ position at its HQ instant for shift ``a + b (t - t0)``: ``(F, 2)``, and
        its image velocity ``(F, 2)`` px/µs (from the bracketing LQ frames).

        Linear between the two LQ frames around the instant (a cubic through four frames was
        tried on simulated walking people and gave the same accuracy at a higher cost).
        """
        s = self.shift_per_feature(a_us, b)
        k = (self.rel_stamps <= s[:, None]).sum(axis=1) - 1
        M = self.rel_stamps.shape[1]
        k = np.clip(k, 0, M - 2)
        rows = np.arange(len(self))
        t1, t2 = self.rel_stamps[rows, k], self.rel_stamps[rows, k + 1]
        p1, p2 = self.tracks[rows, k], self.tracks[rows, k + 1]
        with np.errstate(invalid="ignore", divide="ignore"):
            alpha = (s - t1) / (t2 - t1)
            vel = (p2 - p1) / (t2 - t1)[:, None]
            pos = p1 + alpha[:, None] * (p2 - p1)
        return pos, vel

    def residuals(self, a_us: float, b: float = 0.0) -> np.ndarray:
        """Eq. 31 terms ``||pi(T X_k) - p_k(t + Delta)||`` in pixels, ``(F,)`` (NaN outside the windows)."""
        pos, _ = self.lq_positions(a_us, b)
        return np.linalg.norm(self.pred - pos, axis=1)

    def __call__(self, a_us: float, b: float = 0.0) -> float:
        """Mean robust eq. 31 loss at shift ``a + b (t - t0)`` (pixels squared)."""
        self.evaluations += 1
        r = self.residuals(a_us, b)
        r = r[np.isfinite(r)]
        return float(np.mean(cauchy(r, self.scale))) if r.size else float("inf")


@dataclass
class ShiftEstimate:
    """Result of :func:`estimate_time_shift`.

    Attributes:
        time_shift_us: Delta at ``t0_us`` (µs, float). drift_ppm: ``b * 1e6`` (0 for the constant model).
        std_us: one-sigma uncertainty of Delta from the Gauss-Newton information (inf if none).
        observable: False when the data cannot determine Delta (then ``reason`` says why).
        model: ``"constant"``, ``"linear"`` or ``"declared"``.
        grid_us, grid_loss: the coarse scan (loss against Delta, for the report).
        T_init: ``T_lqcolor_hqdepth`` used by the final evaluation.
        n_probes, n_features, n_moving: what the estimate rests on.
        segments: per time segment ``(t_mid_us, Delta_us)`` local estimates (drift diagnostic).
    """

    time_shift_us: float
    std_us: float
    observable: bool
    model: str
    drift_ppm: float
    t0_us: int
    grid_us: np.ndarray
    grid_loss: np.ndarray
    T_init: Transform
    n_probes: int
    n_features: int
    n_moving: int
    reason: str = ""
    evaluations: int = 0
    segments: list[tuple[float, float]] = field(default_factory=list)
    range_us: tuple[int, int] = (-DEFAULT_RANGE_US, DEFAULT_RANGE_US)

    def shift_at(self, t_hq_us) -> np.ndarray:
        """Delta(t) in µs (float) at HQ stamps ``t_hq_us``."""
        t = np.asarray(t_hq_us, np.float64)
        return self.time_shift_us + self.drift_ppm * 1e-6 * (t - self.t0_us)

    def to_dict(self) -> dict:
        return {"kind": self.model, "a_us": float(self.time_shift_us), "b_ppm": float(self.drift_ppm),
                "t0_us": int(self.t0_us), "std_us": float(self.std_us) if np.isfinite(self.std_us) else None,
                "observable": bool(self.observable), "reason": self.reason, "probes": self.n_probes,
                "features": self.n_features, "moving_features": self.n_moving,
                "range_us": [int(self.range_us[0]), int(self.range_us[1])],
                "segments": [{"t_mid_us": float(t), "shift_us": float(d)} for t, d in self.segments]}


def _refine_T(loss: ShiftLoss, a: float, b: float, *, inlier_px: float, static_only: bool = False) -> Transform:
    """Refit ``T_ex`` with the LQ positions interpolated at shift ``a``; with ``static_only`` on the
    static features alone (their LQ position does not depend on Delta) when there are enough."""
    pos, _ = loss.lq_positions(a, b)
    ok = np.all(np.isfinite(pos), axis=1)
    use = ok & loss.static if static_only and (ok & loss.static).sum() >= MIN_STATIC else ok
    fit = fit_extrinsics(loss.points[use], pos[use], loss.K, T_init=loss.T, inlier_px=inlier_px)
    return fit.T


def _search_constant(loss: ShiftLoss, lo: float, hi: float, step: float, b: float = 0.0):
    grid = np.arange(lo, hi + step / 2, step)
    vals = np.array([loss(g, b) for g in grid])
    i = int(np.nanargmin(vals))
    a0, a1 = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    res = minimize_scalar(lambda a: loss(a, b), bounds=(a0, a1), method="bounded", options={"xatol": 1.0})
    best = float(res.x) if res.fun <= vals[i] else float(grid[i])
    return best, grid, vals


def _information(loss: ShiftLoss, a: float, b: float, *, moving_px: float):
    """(std of Delta in µs, number of moving inlier features, residual scale px)."""
    pos, vel = loss.lq_positions(a, b)
    r = loss.pred - pos
    rn = np.linalg.norm(r, axis=1)
    finite = np.isfinite(rn) & np.all(np.isfinite(vel), axis=1)
    if not finite.any():
        return float("inf"), 0, float("nan")
    sigma = 1.4826 * np.median(np.abs(r[finite])) + 1e-3  # per coordinate, robust
    inl = finite & (rn < 3 * sigma * np.sqrt(2))
    # a feature "moves" when its straight-line displacement over the window exceeds moving_px and
    # is clearly above its own tracking noise (noise alone never looks like motion)
    noise = max(float(np.median(loss.track_noise_px)), 1e-3)  # the session's tracking noise (robust)
    moving = inl & (loss.motion_px > np.maximum(moving_px, 6 * np.maximum(loss.track_noise_px, noise)))
    info = float(np.sum(vel[moving] ** 2)) / sigma ** 2
    std = 1.0 / np.sqrt(info) if info > 0 else float("inf")
    return std, int(moving.sum()), float(sigma)


def estimate_time_shift(probes: list[Probe], K_lq_color: Intrinsics, *, T_init: Transform | None = None,
                        range_us: tuple[int, int] = (-DEFAULT_RANGE_US, DEFAULT_RANGE_US),
                        step_us: int = DEFAULT_STEP_US, model: str = "constant", drift_ppm: float | None = None,
                        declared_shift_us: float | None = None, scale_px: float = 1.5, inlier_px: float = 2.0,
                        iterations: int = 3, max_std_us: float = 5000.0, min_moving: int = 30,
                        moving_px: float = 1.0, t0_us: int | None = None,
                        model_error_us: float = MODEL_ERROR_US) -> ShiftEstimate:
    """Find Delta (and, with ``model="linear"``, the drift) from probes; see the module docstring.

    Args:
        probes: from :class:`Probe` (features computed once per frame). K_lq_color: LQ colour camera.
        T_init: start for ``T_lqcolor_hqdepth``; default PnP+RANSAC on the anchor pairs.
        range_us: search range of Delta (µs). step_us: coarse scan step.
        model: ``"constant"`` or ``"linear"`` (Delta(t) = a + b (t - t0)).
        drift_ppm: declared drift (used as given: only ``a`` is searched).
        declared_shift_us: declared Delta (used as given: no search, the loss is still scanned).
        max_std_us, min_moving, moving_px: the observability test.
        model_error_us: the error shared by every probe of a session, added in quadrature to the stated
            deviation (:data:`MODEL_ERROR_US`; 0 for data with no error but the features' own noise).
    Raises:
        UnobservableError: static scene / no moving features / too uncertain (``estimate`` attached).
        ShiftRangeError: the minimum lies on the edge of the range (``estimate`` attached).
        AssociationError: no probe has LQ frames around it for the whole range.
    """
    if model not in ("constant", "linear"):
        raise OptionError(f"time model must be 'constant' or 'linear', got {model!r}", option="time_model")
    lo, hi = float(range_us[0]), float(range_us[1])
    if not hi > lo:
        raise OptionError(f"shift range is empty: [{lo:.0f}, {hi:.0f}] us", option="shift_range_ms")
    probes = [p for p in probes if p.n_features > 0 and p.tracks.shape[0] >= 2]
    if not probes:
        raise AssociationError("no HQ frame has LQ frames around it for the whole shift range: "
                               "the streams do not overlap in time (or are too short for the range)")
    if T_init is None:
        T_init = _initial_transform(probes, K_lq_color, inlier_px=inlier_px)
    loss = ShiftLoss(probes, T_init, K_lq_color, scale_px=scale_px, t0_us=t0_us)
    b = 0.0 if drift_ppm is None else drift_ppm * 1e-6
    log.debug("shift search: %d probes, %d features tracked through their windows", _n_probes(loss), len(loss))
    if declared_shift_us is not None:
        return _declared_estimate(loss, float(declared_shift_us), b, range_us=(lo, hi), step_us=step_us,
                                  inlier_px=inlier_px, moving_px=moving_px)
    a, grid, vals = _search_constant(loss, lo, hi, step_us, b)
    for it in range(max(iterations - 1, 0)):
        # first with T_ex from the static features alone (decoupled from Delta), then, Delta being
        # close, from all features at their interpolated positions (more of them, more precise)
        loss.set_transform(_refine_T(loss, a, b, inlier_px=inlier_px, static_only=(it == 0)))
        a, grid, vals = _search_constant(loss, lo, hi, step_us, b)
    segments = _segments(loss, a, b, step_us)
    if model == "linear" and drift_ppm is None:
        a, b = _fit_drift(loss, a, segments, inlier_px=inlier_px)
    std_feat, n_moving, _ = _information(loss, a, b, moving_px=moving_px)
    # features of one probe share errors (T_ex, the motion of one limb, tracking on a deforming
    # surface): the scatter of the per-probe estimates gives an honest standard error where the
    # per-feature statistics alone would claim too much
    std = float(np.hypot(max(std_feat, _probe_scatter(loss, a, b, step_us)), model_error_us))
    est = ShiftEstimate(time_shift_us=a, std_us=std, observable=True,
                        model=model if drift_ppm is None else "constant+declared drift", drift_ppm=b * 1e6,
                        t0_us=int(loss.t0), grid_us=grid, grid_loss=vals, T_init=loss.T, n_probes=_n_probes(loss),
                        n_features=len(loss), n_moving=n_moving, reason="", evaluations=loss.evaluations,
                        segments=segments, range_us=(int(lo), int(hi)))
    log.debug("shift %.0f us +- %.0f us from %d moving of %d features (%d loss evaluations)", a, std, n_moving,
              len(loss), loss.evaluations)
    _check_observable(est, std_feat=std_feat, step_us=step_us, max_std_us=max_std_us, min_moving=min_moving)
    return est


def _n_probes(loss: ShiftLoss) -> int:
    return len(set(loss.probe_id.tolist()))


def _initial_transform(probes: list[Probe], K: Intrinsics, *, inlier_px: float) -> Transform:
    """PnP + RANSAC on the anchor pairs, of the features that do not move if there are enough."""
    X, px, still = [], [], []
    for p in probes:
        X.append(p.points)
        px.append(p.tracks[p.anchor])
        span = np.nanmax(p.tracks, axis=0) - np.nanmin(p.tracks, axis=0)
        still.append(np.all(np.isfinite(p.tracks), axis=(0, 2)) & (np.linalg.norm(span, axis=1) < STATIC_PX))
    X, px, still = np.concatenate(X), np.concatenate(px), np.concatenate(still)
    use = still if still.sum() >= MIN_STATIC else np.ones(X.shape[0], bool)
    return fit_extrinsics(X[use], px[use], K, inlier_px=inlier_px).T


def _declared_estimate(loss: ShiftLoss, a: float, b: float, *, range_us: tuple[float, float], step_us: int,
                       inlier_px: float, moving_px: float) -> ShiftEstimate:
    """Delta as declared in the session: no search; the loss is still scanned (for the report)."""
    lo, hi = range_us
    grid = np.arange(lo, hi + step_us / 2, step_us)
    vals = np.array([loss(g, b) for g in grid])
    loss.set_transform(_refine_T(loss, a, b, inlier_px=inlier_px))
    std, n_moving, _ = _information(loss, a, b, moving_px=moving_px)
    return ShiftEstimate(time_shift_us=a, std_us=std, observable=True, model="declared", drift_ppm=b * 1e6,
                         t0_us=int(loss.t0), grid_us=grid, grid_loss=vals, T_init=loss.T, n_probes=_n_probes(loss),
                         n_features=len(loss), n_moving=n_moving,
                         reason="declared in session.json (clock_facts.time_shift_us)",
                         evaluations=loss.evaluations, range_us=(int(lo), int(hi)))


def _fit_drift(loss: ShiftLoss, a: float, segments, *, inlier_px: float) -> tuple[float, float]:
    """The linear model's ``(a, b)``: Nelder-Mead from the segments' slope, T_ex refitted, again."""
    res = minimize(lambda x: loss(x[0], x[1] * 1e-6), x0=[a, _slope_ppm(segments, loss.t0)], method="Nelder-Mead",
                   options={"xatol": 0.5, "fatol": 1e-9, "initial_simplex": [[a, 0.0], [a + 500, 0.0], [a, 20.0]]})
    a, b = float(res.x[0]), float(res.x[1]) * 1e-6
    loss.set_transform(_refine_T(loss, a, b, inlier_px=inlier_px))
    res = minimize(lambda x: loss(x[0], x[1] * 1e-6), x0=[a, b * 1e6], method="Nelder-Mead",
                   options={"xatol": 0.2, "fatol": 1e-10})
    return float(res.x[0]), float(res.x[1]) * 1e-6


def _check_observable(est: ShiftEstimate, *, std_feat: float, step_us: float, max_std_us: float,
                      min_moving: int) -> None:
    """Raise (with the estimate attached, marked unobservable) when the edge or the motion says so."""
    a, (lo, hi) = est.time_shift_us, est.range_us
    static = est.n_moving < min_moving
    if min(a - lo, hi - a) < 0.25 * step_us and not static:
        est.observable = False
        est.reason = (f"the best shift {a / 1000:.1f} ms lies on the edge of the search range "
                      f"[{lo / 1000:.0f}, {hi / 1000:.0f}] ms; the true shift may lie outside it")
        raise ShiftRangeError(f"{est.reason}: widen the search range", estimate=est, option="shift_range_ms")
    if static or not std_feat <= max_std_us:
        est.observable = False
        est.reason = (f"only {est.n_moving} features move (need {min_moving}); the motion determines the shift to "
                      f"{std_feat:.0f} us (limit {max_std_us:.0f} us): the scene is static or nearly so")
        raise UnobservableError(f"time shift unobservable: {est.reason}", estimate=est)


def _probe_scatter(loss: ShiftLoss, a: float, b: float, step_us: float) -> float:
    """Standard error of Delta from the spread of one-probe estimates (robust), µs; 0 if too few."""
    _, est = probe_estimates(loss, a, b, step_us)
    if est.size < 4:
        return 0.0
    return float(1.4826 * np.median(np.abs(est - np.median(est))) / np.sqrt(est.size))


def probe_estimates(loss: ShiftLoss, a: float, b: float, step_us: float) -> tuple[np.ndarray, np.ndarray]:
    """Delta from each probe alone (probes with at least 5 moving features), within ``a +- step_us``:
    ``(probe ids, estimates µs)``, in time order."""
    pids = np.unique(loss.probe_id)
    ids, est = [], []
    for pid in pids:
        keep = loss.probe_id == pid
        moving = keep & (loss.motion_px > np.maximum(1.0, 6 * loss.track_noise_px))
        if moving.sum() < 5:
            continue
        res = minimize_scalar(_SubLoss(loss, keep, b), bounds=(a - step_us, a + step_us), method="bounded",
                              options={"xatol": 5.0})
        ids.append(pid)
        est.append(res.x)
    return np.asarray(ids, np.int64), np.asarray(est, np.float64)


def block_jackknife_se(loss: ShiftLoss, a: float, b: float, step_us: float, *, blocks: int = 6) -> float:
    """Standard error of Delta by a delete-one-block jackknife over ``blocks`` contiguous blocks of
    probes (time order), µs; 0 with fewer than ``2 blocks`` probes. Errors shared by neighbouring
    probes (the same limbs in motion, one stretch of the scene) stay inside a block, so they count,
    where the scatter of one-probe estimates treats every probe as independent."""
    pids = np.unique(loss.probe_id)
    if pids.size < 2 * blocks:
        return 0.0
    est = []
    for part in np.array_split(pids, blocks):
        keep = ~np.isin(loss.probe_id, part)
        res = minimize_scalar(_SubLoss(loss, keep, b), bounds=(a - step_us, a + step_us), method="bounded",
                              options={"xatol": 2.0})
        est.append(res.x)
    est = np.asarray(est)
    return float(np.sqrt((blocks - 1) / blocks * np.sum((est - est.mean()) ** 2)))


def _segments(loss: ShiftLoss, a: float, b: float, step_us: float, n: int = 4) -> list[tuple[float, float]]:
    """Local Delta estimates in ``n`` time segments of the probes (a drift shows as a slope)."""
    out = []
    pids = np.unique(loss.probe_id)
    if pids.size < 2 * n:
        return out
    t_probe = np.array([loss.t_hq[loss.probe_id == p][0] for p in pids])
    order = np.argsort(t_probe)
    for chunk in np.array_split(pids[order], n):
        keep = np.isin(loss.probe_id, chunk)
        sub = _SubLoss(loss, keep)
        center = a + b * (np.mean(loss.t_hq[keep]) - loss.t0)
        res = minimize_scalar(sub, bounds=(center - step_us, center + step_us), method="bounded",
                              options={"xatol": 2.0})
        out.append((float(np.mean(loss.t_hq[keep])), float(res.x)))
    return out


class _SubLoss:
    """The loss restricted to some features, as a function of ``a`` (drift ``b`` fixed)."""

    def __init__(self, loss: ShiftLoss, keep: np.ndarray, b: float = 0.0) -> None:
        self.loss, self.keep, self.b = loss, keep, b

    def __call__(self, a: float) -> float:
        r = self.loss.residuals(a, self.b)[self.keep]
        r = r[np.isfinite(r)]
        return float(np.mean(cauchy(r, self.loss.scale))) if r.size else float("inf")


def _slope_ppm(segments, t0) -> float:
    if len(segments) < 2:
        return 0.0
    t = np.array([s[0] for s in segments]) - t0
    d = np.array([s[1] for s in segments])
    if np.ptp(t) <= 0:
        return 0.0
    return float(np.polyfit(t, d, 1)[0] * 1e6)
