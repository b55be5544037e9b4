"""Residuals stratified by the signatures of the effects (issue 12, item 1). Pure numpy, no I/O.

Each *signature* pairs a response derived from the residuals with a covariate an effect would
make it depend on:

=================== ======================================== ====================== ==================
signature           response                                  covariate              points to
=================== ======================================== ====================== ==================
velocity            feature residual along its motion, px    image speed, px/ms     time shift
velocity_x_time     time residual of moving features, ms      time in session, s     clock drift
velocity_x_row      time residual of moving features, ms      LQ image row (-.5..5)  LQ rolling shutter
velocity_x_hq_row   time residual of moving features, ms      HQ image row           HQ rolling shutter
radius              radial feature residual, px               radius (normalised)^2  LQ lens
hq_radius           radial feature residual, px               HQ radius^2            HQ lens
depth               relative depth residual, %                1 / depth, 1/m         depth offset
constant            relative depth residual, %                depth, m (flat = scale) depth scale
time_in_session     |feature residual|, px                    time in session, s     anything time-varying
frame_interval      per-pair depth residual, %                LQ frame interval      drops, duplicates
=================== ======================================== ====================== ==================

The *time residual* of a moving feature is ``-(r . v) / |v|^2`` (the time error that would
explain its residual ``r`` given its image velocity ``v``). Per signature :func:`signature`
bins the covariate at its quantiles and gives each bin's robust mean response with its standard
error, the slope of the response on the covariate with its standard error (least squares, each
bin's scatter) and a chi-square of the bin means against their mean: ``z = slope / se`` and the
chi-square p-value say whether the residual still depends on the covariate.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

#: |z| above which a signature counts as structure left in the residual
STRUCTURE_Z = 4.0


@dataclass
class Signature:
    """One stratified table: bins of the covariate with the response's mean and standard error."""

    name: str
    covariate: str
    response: str
    centers: np.ndarray
    means: np.ndarray
    sems: np.ndarray
    counts: np.ndarray
    slope: float
    slope_se: float
    chi2_p: float
    points_to: str = ""
    level: bool = False  # the statistic is the overall mean (against 0), not the slope
    level_mean: float = 0.0
    level_se: float = 0.0
    sample_x: np.ndarray = field(default_factory=lambda: np.zeros(0))
    sample_y: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def z(self) -> float:
        if self.level:
            return float(self.level_mean / self.level_se) if self.level_se > 0 else 0.0
        return float(self.slope / self.slope_se) if self.slope_se > 0 else 0.0

    @property
    def structured(self) -> bool:
        return abs(self.z) > STRUCTURE_Z

    def to_dict(self) -> dict:
        return {"name": self.name, "covariate": self.covariate, "response": self.response,
                "points_to": self.points_to, "statistic": "mean" if self.level else "slope",
                "mean": self.level_mean, "mean_se": self.level_se, "slope": self.slope, "slope_se": self.slope_se, "z": self.z,
                "chi2_p": self.chi2_p,
                "bins": [{"center": float(c), "mean": float(m), "sem": float(s), "n": int(n)}
                         for c, m, s, n in zip(self.centers, self.means, self.sems, self.counts)]}


def signature(name: str, x, y, *, covariate: str, response: str, points_to: str = "", bins: int = 8,
              group=None, sample: int = 2000, seed: int = 0, level: bool = False) -> Signature:
    """Stratify response ``y`` by covariate ``x`` (finite pairs only).

    ``group`` (optional, per value): the standard errors treat each group as one independent
    unit (values of one probe or one frame pair share errors), via group means within a bin.
    """
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    ok = np.isfinite(x) & np.isfinite(y)
    g = None if group is None else np.asarray(group)[ok]
    x, y = x[ok], y[ok]
    if x.size < 2 * bins:
        e = np.zeros(0)
        return Signature(name, covariate, response, e, e, e, e.astype(int), 0.0, 0.0, 1.0, points_to)
    edges = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)))
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, max(edges.size - 2, 0))
    centers, means, sems, counts, units = [], [], [], [], []
    for b in range(edges.size - 1):
        sel = idx == b
        if sel.sum() < 3:
            continue
        yb = y[sel]
        lo, hi = np.percentile(yb, [5, 95])  # trim each bin's far tails (mismatches): robust means
        inner = (yb >= lo) & (yb <= hi)
        yb = yb[inner]
        if g is not None:  # one value per group: the group means
            gb = g[sel][inner]
            u, inv = np.unique(gb, return_inverse=True)
            yb = np.bincount(inv, yb) / np.bincount(inv)
        centers.append(float(np.median(x[sel])))
        means.append(float(np.mean(yb)))
        units.append(yb - np.mean(yb))
        counts.append(int(sel.sum()))
    # standard errors from the pooled scatter of the units (values or group means) around their bin
    # means: a bin holding a few groups only (time bins of a few probes) gets no lucky tiny error
    dev = np.concatenate(units) if units else np.zeros(0)
    dof = dev.size - len(units)
    sd = float(np.sqrt(np.sum(dev ** 2) / dof)) if dof > 0 else float("inf")
    sems = [sd / np.sqrt(u.size) if sd > 0 else float("inf") for u in units]
    c, m, s = np.array(centers), np.array(means), np.array(sems)
    slope, slope_se, p = _slope(c, m, s)
    lm, lse = _level(y, g)
    rng = np.random.default_rng(seed)
    pick = rng.choice(x.size, size=min(sample, x.size), replace=False)
    return Signature(name, covariate, response, c, m, s, np.array(counts), slope, slope_se, p, points_to, level,
                     lm, lse, x[pick], y[pick])


def _level(y: np.ndarray, g) -> tuple[float, float]:
    """Mean of ``y`` and its standard error (groups as units when given)."""
    if g is not None:
        _, inv = np.unique(g, return_inverse=True)
        y = np.bincount(inv, y) / np.bincount(inv)
    if y.size < 2:
        return float(np.mean(y)) if y.size else 0.0, 0.0
    return float(np.mean(y)), float(np.std(y, ddof=1) / np.sqrt(y.size))


def _slope(c: np.ndarray, m: np.ndarray, s: np.ndarray) -> tuple[float, float, float]:
    ok = np.isfinite(s) & (s > 0)
    if ok.sum() < 3:
        return 0.0, 0.0, 1.0
    c, m, w = c[ok], m[ok], 1.0 / s[ok] ** 2
    A = np.stack([np.ones_like(c), c], axis=1)
    N = A.T @ (A * w[:, None])
    try:
        cov = np.linalg.inv(N)
    except np.linalg.LinAlgError:
        return 0.0, 0.0, 1.0
    beta = cov @ (A.T @ (w * m))
    mean = float(np.sum(w * m) / np.sum(w))
    x2 = float(np.sum(w * (m - mean) ** 2))
    return float(beta[1]), float(np.sqrt(cov[1, 1])), float(chi2.sf(x2, ok.sum() - 1))


def feature_signatures(data, residual: np.ndarray, *, shift_us: np.ndarray, stamps: np.ndarray | None = None
                       ) -> list[Signature]:
    """The feature-residual signatures (table above) of :class:`align.loop.features.FeatureData`.

    ``residual``: ``(2F,)`` rows of the fitted model; ``shift_us``: each feature's instant in its
    window; ``stamps``: the sample stamps the model used (default ``data.rel_us``)."""
    from align.loop.features import interpolate_tracks

    st = data.rel_us if stamps is None else stamps
    F = len(data)
    r = residual.reshape(F, 2)
    used = np.any(r != 0, axis=1)
    k = np.clip((st <= shift_us[:, None]).sum(axis=1) - 1, 0, st.shape[1] - 2)
    rows = np.arange(F)
    with np.errstate(invalid="ignore", divide="ignore"):
        v = (data.tracks[rows, k + 1] - data.tracks[rows, k]) / (st[rows, k + 1] - st[rows, k])[:, None] * 1e3
    pos, _ = interpolate_tracks(data.tracks, st, shift_us)
    speed = np.linalg.norm(v, axis=1)
    moving = used & (speed > 0.05)  # px/ms: 1.7 px per 33 ms frame
    with np.errstate(invalid="ignore", divide="ignore"):
        along = np.sum(r * v, axis=1) / speed
        dt_ms = np.where(moving, np.sum(r * v, axis=1) / speed ** 2, np.nan)  # pred - pos = v * (t_true - s)
    K, Kh = data.K_lq, data.K_hq
    nx, ny = (pos[:, 0] - K.cx) / K.fx, (pos[:, 1] - K.cy) / K.fy
    rad2 = nx ** 2 + ny ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        radial = (r[:, 0] * nx + r[:, 1] * ny) / np.sqrt(rad2)
    hx, hy = (data.hq_xy[:, 0] - Kh.cx) / Kh.fx, (data.hq_xy[:, 1] - Kh.cy) / Kh.fy
    t_s = (data.t_hq_us - data.t0_us) * 1e-6
    g = data.probe
    row = (pos[:, 1] + 0.5) / K.height - 0.5
    hq_row = (data.hq_xy[:, 1] + 0.5) / Kh.height - 0.5
    U = np.where(used, 1.0, np.nan)
    return [
        signature("velocity", speed * U, along * U, covariate="image speed, px/ms",
                  response="residual along the motion, px", points_to="time shift", group=g),
        signature("velocity_x_time", t_s, dt_ms, covariate="time in session, s", response="time residual, ms",
                  points_to="clock_drift", group=g),
        signature("velocity_x_row", row, dt_ms, covariate="LQ image row (-0.5 top .. 0.5 bottom)",
                  response="time residual, ms", points_to="rolling_shutter_lq", group=g),
        signature("velocity_x_hq_row", hq_row, dt_ms, covariate="HQ image row (-0.5 .. 0.5)",
                  response="time residual, ms", points_to="rolling_shutter_hq", group=g),
        signature("radius", rad2 * U, radial * U, covariate="LQ radius^2 (normalised)",
                  response="radial residual, px", points_to="lens_lq_k1", group=g),
        signature("hq_radius", (hx ** 2 + hy ** 2) * U, radial * U, covariate="HQ radius^2 (normalised)",
                  response="radial residual, px", points_to="lens_hq_k1", group=g),
        signature("time_in_session", t_s * U, np.linalg.norm(r, axis=1) * U, covariate="time in session, s",
                  response="|feature residual|, px", points_to="", group=g),
    ]


def depth_signatures(data, residual: np.ndarray, *, pair_interval=None, pair_residual=None) -> list[Signature]:
    """The depth-residual signatures of :class:`align.loop.effects.depth.DepthData` (``residual`` relative).

    ``pair_interval``/``pair_residual``: per pair, the LQ frame interval before it (in frame periods;
    0 for a duplicated frame) and its depth residual (relative)."""
    out = [signature("depth", 1.0 / data.z_ref, 100 * residual, covariate="1 / depth, 1/m",
                     response="relative depth residual, %", points_to="depth_offset", group=data.pair),
           signature("constant", data.z_ref, 100 * residual, covariate="depth, m",
                     response="relative depth residual, %", points_to="depth_scale", group=data.pair, level=True),
           signature("depth_radius", data.radius ** 2, 100 * residual, covariate="LQ radius^2 (normalised)",
                     response="relative depth residual, %", points_to="lens_lq_k1", group=data.pair),
           signature("depth_time", (data.t_us - data.t_us.min()) * 1e-6, 100 * residual,
                     covariate="time in session, s", response="relative depth residual, %", group=data.pair)]
    if pair_interval is not None:
        out.append(signature("frame_interval", pair_interval, 100 * np.asarray(pair_residual),
                             covariate="LQ frame interval before the pair, periods (0: duplicate)",
                             response="per-pair depth residual, %", points_to="frames", bins=4))
    return out
