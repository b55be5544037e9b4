"""Time shifts between the views of a calibrated multi-view rig, from their depth.

Pure (numpy, :class:`align.warp.DepthWarper`), no I/O: the caller reads the frames.

Why. Each view's time shift against the rig's reference sensor is first searched from colour
features (:mod:`align.time_shift`, eq. 28-29): the features on moving content must match across
the baseline. Between views 1-1.5 m and 20-30 deg apart only 6-20 moving features match (30 are
needed) and the shift is written as an unobservable placeholder of 0; on the demo's four-view
corpus a DDD training sample's views were then 25-47 ms apart in scene time (issue 11, session 7).
Once the rig is calibrated (:mod:`align.rig_refine`: from static depth, so the clocks do not
matter there), depth needs no matches: a frame of view ``v`` warped into the reference ``r``
agrees with ``r``'s frame of the *same instant* up to noise and calibration error, and what moves
disagrees by its motion over the time between the two exposures.

Model. Stamps are each sensor's host stamps (dejittered); an instant stamped ``t_r`` by ``r`` is
stamped ``t_v = t_r + Delta`` by ``v`` (``Delta = time_shift_us``, the constant model of
:mod:`align.time_shift`). For reference frame ``i`` and view frame ``j`` (frame offset
``dt_ij = t_v[j] - t_r[i]``) the disagreement is

    c_ij = ( sum_F min(|W_vr(D_v[j]) - D_r[i]|, tau) / |M_r[i]|
           + sum_G min(|W_rv(D_r[i]) - D_v[j]|, tau) / |M_v[j]| ) / 2

with ``W_vr`` the z-buffered warp from ``v``'s depth camera into ``r``'s through the rig
(``T_r_v``, :class:`align.warp.DepthWarper`), ``M_r[i]`` the *foreground* of ``r``'s frame (in front
of ``r``'s own background: the :func:`align.roi.foreground_mask` rule against
:func:`align.roi.background_depth` of ``r``'s frames), ``F`` the pixels of ``r``'s image with both
depths where either the frame or the warped one is foreground, less those where ``r``'s surface
lies more than :data:`HIDDEN_M` in front of the warped one (the warped point is hidden from ``r``:
no contradiction), and ``G``, ``M_v`` the same in ``v``'s image; ``tau`` = :data:`TRUNCATE_M` (a
person seen against the wall behind it by the other camera counts ``tau``, not metres). Static
content is left out (it agrees at any ``dt``). Per reference frame ``c_i(dt)`` is linear between
its frame offsets; their mean over ``i`` is the cost curve

    C(Delta) = mean_i c_i(Delta).

``C`` is smallest at the frame offset nearest the true ``Delta`` and grows roughly linearly with
``|dt - Delta|`` (speed times time); with equal frame rates it is sampled only at the offsets
``phi + kT`` (``T`` the view's frame period), so ``Delta`` is the vertex of the V ``b + a |dt -
Delta|`` through the smallest sample ``tau_0`` and the curve at ``tau_0 +- T`` (exact for a V). The
V is not symmetric on the simulator (what moves leaves or enters the other camera's view
differently before and after the instant): the vertex was up to 11 ms off the truth there, the
smallest cost at the frame offset nearest to it. Uncertainty: the vertex's sd over a bootstrap
of the reference frames combined with :data:`SHAPE_SD_US` for that asymmetry. Unobservable (the
placeholder stays) when too few foreground pixels were compared (nothing moves), the V does not
rise on both sides, or the sd exceeds a quarter period (the pairing itself would be uncertain).

Pairing by the found ``Delta`` (eq. 28 at that shift) puts a view's frame within half a frame
period (plus the error of ``Delta``) of the reference frame's instant; at equal frame rates the
views' frame phases leave up to ``T/2`` that no shift removes.

Measured on the simulator (issue 11, the ddd note of session 8): see :func:`sync_view`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from align.errors import AlignError
from align.roi import background_depth, foreground_mask
from align.warp import DepthWarper
from capture.camera import Intrinsics, Transform

#: residuals are truncated here (metres): a person seen against the wall by the other view counts this much
TRUNCATE_M = 0.1
#: a target surface this far (metres) in front of a warped point hides it: that pixel is no contradiction
HIDDEN_M = 0.05
#: fewest compared foreground pixels per reference frame, on average, for an observable shift
MIN_PIXELS = 200
#: sd (µs) of the vertex's systematic error, added to the bootstrap's: the V is not symmetric (what
#: moves leaves or enters the other camera's view differently before and after the instant). On the
#: simulator's four-view sessions (seeds 2001, 2015; 6 views) the vertex was 0.9-11 ms off the truth (RMS
#: 6.0 ms) while the bootstrap sd was 0.2-0.5 ms; held out (seeds 2016, 2017; 6 views, through
#: ``depthbench align``): 0.2-6.1 ms, RMS 4.3 ms.
SHAPE_SD_US = 7000.0
#: the shift is unobservable when its bootstrap sd exceeds this share of the frame period
MAX_SD_PERIODS = 0.25


@dataclass(frozen=True)
class DepthFrames:
    """Depth frames of one sensor: ``depth`` ``(N, H, W)`` float32 metres (NaN = none),
    ``stamps_us`` ``(N,)`` int64 host stamps (dejittered), ``K`` the depth camera."""

    depth: np.ndarray
    stamps_us: np.ndarray
    K: Intrinsics

    def __post_init__(self) -> None:
        if self.depth.ndim != 3 or self.depth.shape[0] != len(self.stamps_us) or self.depth.shape[1:] != self.K.shape:
            raise AlignError(f"depth frames {self.depth.shape} do not match {len(self.stamps_us)} stamps and a "
                             f"{self.K.width}x{self.K.height} camera")


@dataclass
class ViewSync:
    """Result of :func:`sync_view`.

    ``time_shift_us``: ``Delta`` (µs; the placeholder's value when unobservable is the caller's).
    ``std_us``: bootstrap sd over the reference frames. ``grid_us``, ``grid_cost``: ``C`` (metres)
    on a 1 ms grid over the range. ``frames``: reference frames used; ``pixels``: compared
    foreground pixels per reference frame (mean); ``slope_mm_per_ms``: the V's ``a``.
    """

    time_shift_us: float
    std_us: float
    observable: bool
    reason: str
    grid_us: np.ndarray
    grid_cost: np.ndarray
    frames: int
    pixels: float
    slope_mm_per_ms: float
    period_us: float
    boot_us: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def to_dict(self) -> dict:
        return {"method": "depth", "time_shift_us": float(self.time_shift_us),
                "std_us": float(self.std_us) if np.isfinite(self.std_us) else None, "observable": bool(self.observable),
                "reason": self.reason, "frames": int(self.frames), "pixels_per_frame": float(self.pixels),
                "slope_mm_per_ms": float(self.slope_mm_per_ms), "period_us": float(self.period_us)}


def frames_to_read(t_ref_us: np.ndarray, t_view_us: np.ndarray, *, range_us: int, max_frames: int = 24
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the reference frames to use (up to ``max_frames``, evenly spread) and of the view
    frames they need: every view frame within ``range_us`` plus 1.5 periods of a used reference
    frame (the V needs the curve one period beyond the range). Reference frames whose window is not
    covered by the view's stamps are left out."""
    t_ref, t_view = np.asarray(t_ref_us, np.int64), np.asarray(t_view_us, np.int64)
    if t_view.size < 3 or t_ref.size < 1:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    reach = range_us + 1.5 * float(np.median(np.diff(t_view)))
    ok = np.flatnonzero((t_ref - reach >= t_view[0]) & (t_ref + reach <= t_view[-1]))
    if ok.size == 0:
        return ok, ok
    ref = ok[np.unique(np.linspace(0, ok.size - 1, min(max_frames, ok.size)).round().astype(int))]
    need = np.zeros(t_view.size, bool)
    for t in t_ref[ref]:
        need |= np.abs(t_view - t) <= reach
    return ref, np.flatnonzero(need)


def _disagreement(warped: np.ndarray, target: np.ndarray, fg_target: np.ndarray, bg_target: np.ndarray,
                  truncate_m: float, hidden_m: float) -> tuple[float, int]:
    """Sum of truncated |warped - target| over the pixels with both depths where either is
    foreground (the warped one against the target's background), leaving out those where the
    target's surface lies more than ``hidden_m`` in front of the warped one (hidden from the target
    camera: no contradiction), and the count of pixels compared."""
    fg_warped = foreground_mask(np.where(np.isfinite(warped), warped, 0), bg_target, min_area_px=0, open_px=0)
    with np.errstate(invalid="ignore"):
        sel = np.isfinite(warped) & np.isfinite(target) & (fg_target | fg_warped) & (target > warped - hidden_m)
    return float(np.minimum(np.abs(warped[sel] - target[sel]), truncate_m).sum()), int(sel.sum())


def pair_costs(ref: DepthFrames, view: DepthFrames, T_ref_view: Transform, *, truncate_m: float = TRUNCATE_M,
               hidden_m: float = HIDDEN_M, reach_us: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``c_ij`` (metres) of every reference frame ``i`` and view frame ``j`` (module docstring),
    their frame offsets ``dt_ij = t_view[j] - t_ref[i]`` (µs) and the compared pixel counts, each
    ``(N_ref, N_view)``; NaN cost where either frame has no foreground or ``|dt_ij| > reach_us`` (None:
    every pair)."""
    dt = view.stamps_us[None, :].astype(np.float64) - ref.stamps_us[:, None].astype(np.float64)
    bg_r, bg_v = background_depth(ref.depth), background_depth(view.depth)
    to_ref = DepthWarper(view.K, ref.K, T_ref_view)
    to_view = DepthWarper(ref.K, view.K, T_ref_view.inverse())
    area_r = max(1, int(100 * ref.K.width * ref.K.height / 640 / 480))   # the alignment's 100 px at 640x480
    area_v = max(1, int(100 * view.K.width * view.K.height / 640 / 480))
    fg_r = [foreground_mask(d, bg_r, min_area_px=area_r) for d in ref.depth]
    fg_v = [foreground_mask(d, bg_v, min_area_px=area_v) for d in view.depth]
    w_vr = [to_ref(d) for d in view.depth]
    w_rv = [to_view(d) for d in ref.depth]
    n_r, n_v = len(ref.depth), len(view.depth)
    cost = np.full((n_r, n_v), np.nan)
    count = np.zeros((n_r, n_v), np.int64)
    for i in range(n_r):
        for j in range(n_v):
            if reach_us is not None and abs(dt[i, j]) > reach_us:
                continue
            s1, k1 = _disagreement(w_vr[j], ref.depth[i], fg_r[i], bg_r, truncate_m, hidden_m)
            s2, k2 = _disagreement(w_rv[i], view.depth[j], fg_v[j], bg_v, truncate_m, hidden_m)
            count[i, j] = k1 + k2
            n1, n2 = int(fg_r[i].sum()), int(fg_v[j].sum())   # what moves, seen by each camera
            if n1 and n2:
                cost[i, j] = (s1 / n1 + s2 / n2) / 2
    return cost, dt, count


def _curve(cost: np.ndarray, dt: np.ndarray, at_us: np.ndarray) -> np.ndarray:
    """``C`` at ``at_us``: per reference frame linear in the frame offset, mean over frames (NaN
    outside a frame's offsets)."""
    rows = []
    for c, d in zip(cost, dt):
        ok = np.isfinite(c)
        order = np.argsort(d[ok])
        x, y = d[ok][order], c[ok][order]
        rows.append(np.interp(at_us, x, y, left=np.nan, right=np.nan) if x.size >= 2 else np.full(at_us.shape, np.nan))
    if not rows:
        return np.full(at_us.shape, np.nan)
    rows = np.array(rows)
    n = np.isfinite(rows).sum(axis=0)
    return np.where(n > 0, np.nansum(rows, axis=0) / np.maximum(n, 1), np.nan)


def v_vertex(cost: np.ndarray, dt: np.ndarray, *, period_us: float, range_us: int) -> tuple[float, float]:
    """``Delta`` and the V's slope (metres per µs; <= 0 when the curve does not rise on both sides)
    from the frames' costs (module docstring): the smallest of ``C`` at the frame offsets within the
    range (widened by half a period: the nearest frame of a shift at the range's end), and ``C`` one
    period either side of it."""
    offsets = np.unique(np.round(dt[np.isfinite(cost)]))
    offsets = offsets[np.abs(offsets) <= range_us + period_us / 2]
    if offsets.size == 0:
        return np.nan, 0.0
    c_off = _curve(cost, dt, offsets)
    if not np.isfinite(c_off).any():
        return np.nan, 0.0
    tau0 = float(offsets[int(np.nanargmin(c_off))])
    cm, c0, cp = _curve(cost, dt, np.array([tau0 - period_us, tau0, tau0 + period_us]))
    if not np.all(np.isfinite([cm, c0, cp])):
        return tau0, 0.0
    hi, lo, sign = (cm, cp, 1.0) if cm >= cp else (cp, cm, -1.0)
    a = (hi - c0) / period_us
    if a <= 0 or lo < c0:
        return tau0, min(a, lo - c0)
    return tau0 + sign * float(np.clip((period_us - (lo - c0) / a) / 2, 0.0, period_us / 2)), float(a)


def sync_view(ref: DepthFrames, view: DepthFrames, T_ref_view: Transform, *, range_us: int = 60_000,
              truncate_m: float = TRUNCATE_M, n_boot: int = 200, seed: int = 0) -> ViewSync:
    """``Delta`` of ``view`` against ``ref`` (``t_view = t_ref + Delta`` for one instant) from the
    depth disagreement of what moves, given ``T_ref_view`` (``view``'s depth camera -> ``ref``'s,
    metres) from the calibrated rig (module docstring). ``range_us``: search ``|Delta| <= range``.
    Frames as :func:`frames_to_read` picks them (reference frames whose window the view covers)."""
    period = float(np.median(np.diff(view.stamps_us)))
    cost, dt, count = pair_costs(ref, view, T_ref_view, truncate_m=truncate_m, reach_us=range_us + 1.5 * period)
    grid = np.arange(-range_us, range_us + 1, 1000, dtype=np.float64)
    curve = _curve(cost, dt, grid)
    near = np.abs(dt) <= range_us + period
    pixels = float(count[near].sum() / max(1, near.sum()))
    est, slope = v_vertex(cost, dt, period_us=period, range_us=range_us)
    rng = np.random.default_rng(seed)
    boot = []
    for _ in range(n_boot):
        k = rng.integers(0, len(cost), len(cost))
        boot.append(v_vertex(cost[k], dt[k], period_us=period, range_us=range_us)[0])
    boot = np.asarray(boot, np.float64)
    sd = float(np.hypot(np.nanstd(boot), SHAPE_SD_US)) if np.isfinite(boot).sum() > 1 else np.inf
    reason = ""
    if pixels < MIN_PIXELS:
        reason = f"too little moving depth seen by both views ({pixels:.0f} foreground pixels per frame pair)"
    elif not np.isfinite(est) or slope <= 0:
        reason = "the depth disagreement of what moves does not rise on both sides of its smallest frame offset"
    elif not sd <= MAX_SD_PERIODS * period:
        reason = f"the shift from depth is uncertain (sd {sd / 1000:.1f} ms over a {period / 1000:.1f} ms frame period)"
    return ViewSync(time_shift_us=float(est) if np.isfinite(est) else 0.0, std_us=sd, observable=not reason,
                    reason=reason, grid_us=grid, grid_cost=curve, frames=len(cost), pixels=pixels,
                    slope_mm_per_ms=1e6 * slope, period_us=period, boot_us=boot)
