"""The feature residual of the alignment as a function of every model parameter. Pure numpy, no I/O.

Data (:class:`FeatureData`, from the probes of the base fit): for feature ``k`` an HQ point
``X_k`` (HQ depth frame, metres) lifted at HQ stamp ``t_k``, its HQ colour pixel ``q_k``, and its
LQ colour track ``p_k(t_j)`` sampled at the stamps ``t_j`` of the LQ frames around it.

Model (:class:`FeatureModel`), eq. 30-31 with the effects of :mod:`align.loop.effects` switched on::

    X'_k    = effects' correction of the lifted point (HQ colour lens)
    pred_k  = pi_LQ(T_ex X'_k)                       (LQ colour lens distortion inside pi_LQ)
    s_k     = Delta(t_k) + effects' time offsets     (drift, HQ colour rolling shutter)
    e_kj    = t_kj + effects' sample offsets         (LQ colour rolling shutter: per track row)
    r_k     = pred_k - p_k(s_k)                      p_k linearly interpolated over e_kj

The residual vector is ``(2F,)`` pixels (x then y per feature; 0 where a feature's instant falls
outside its window). Parameters live in one vector; :attr:`FeatureModel.layout` names its
slices (``pose`` = rotation vector and translation of ``T_ex = T_lqcolor_hqdepth``; ``shift`` =
Delta at ``t0`` in ms; each effect's own). The Jacobian is by central differences with
per-parameter steps (the track interpolation is piecewise linear in time, so analytic
derivatives would be the same segment velocities).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from capture.camera import Intrinsics, Transform


@dataclass
class FeatureData:
    """Packed features of the probes (only those tracked through their whole window).

    Attributes:
        points: ``(F, 3)`` HQ depth-frame points, metres. hq_xy: ``(F, 2)`` their HQ colour pixels.
        tracks: ``(F, M, 2)`` LQ colour pixels per window frame (NaN padding).
        rel_us: ``(F, M)`` LQ stamps minus the feature's HQ stamp, µs (``inf`` padding).
        t_hq_us: ``(F,)`` HQ stamps. probe: ``(F,)`` probe index (0..P-1, in time order).
        t0_us: origin of the drift term. K_lq: LQ colour camera. K_hq: HQ colour camera (as declared).
        T_hqcolor_hqdepth: the HQ's own calibration.
        w_grad: ``(F, 2)`` gradient of inverse depth at each HQ colour pixel, 1/(m px) (0: unknown).
    """

    points: np.ndarray
    hq_xy: np.ndarray
    tracks: np.ndarray
    rel_us: np.ndarray
    t_hq_us: np.ndarray
    probe: np.ndarray
    t0_us: float
    K_lq: Intrinsics
    K_hq: Intrinsics
    T_hqcolor_hqdepth: Transform
    w_grad: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.points.shape[0])

    @property
    def n_probes(self) -> int:
        return int(self.probe.max()) + 1 if len(self) else 0

    def subset(self, keep: np.ndarray) -> "FeatureData":
        return FeatureData(self.points[keep], self.hq_xy[keep], self.tracks[keep], self.rel_us[keep],
                           self.t_hq_us[keep], self.probe[keep], self.t0_us, self.K_lq, self.K_hq,
                           self.T_hqcolor_hqdepth, None if self.w_grad is None else self.w_grad[keep])

    def with_tracks(self, tracks: np.ndarray) -> "FeatureData":
        return FeatureData(self.points, self.hq_xy, tracks, self.rel_us, self.t_hq_us, self.probe, self.t0_us,
                           self.K_lq, self.K_hq, self.T_hqcolor_hqdepth, self.w_grad)


def pack_probes(probes, *, K_lq: Intrinsics, K_hq: Intrinsics, T_hqcolor_hqdepth: Transform, t0_us: float,
                skip_lq_index=None) -> FeatureData:
    """Pack probes (``align.time_shift.Probe``) into :class:`FeatureData`.

    ``skip_lq_index``: LQ colour frame positions to leave out of every track (duplicated frames:
    their stamp is not the instant of their content).
    """
    skip = set(int(i) for i in (skip_lq_index if skip_lq_index is not None else ()))
    probes = sorted((p for p in probes if p.n_features > 0), key=lambda p: p.t_hq_us)
    cols = []
    for p in probes:
        use = np.array([int(j) not in skip for j in p.lq_index], bool)
        tr = p.tracks[use]
        full = np.all(np.isfinite(tr), axis=(0, 2)) if tr.shape[0] >= 2 else np.zeros(tr.shape[1], bool)
        cols.append((p, use, full))
    M = max([int(u.sum()) for _, u, _ in cols] + [2])
    parts = {k: [] for k in ("X", "tr", "rel", "t", "pid", "g")}
    pid = 0
    for p, use, full in cols:
        n = int(full.sum())
        if n == 0:
            continue
        m = int(use.sum())
        tr = np.full((n, M, 2), np.nan)
        tr[:, :m] = np.transpose(p.tracks[use][:, full], (1, 0, 2))
        rel = np.full((n, M), np.inf)
        rel[:, :m] = (p.t_lq_us[use] - p.t_hq_us).astype(np.float64)
        parts["X"].append(p.points[full])
        parts["g"].append(np.zeros((n, 2)) if p.w_grad is None else p.w_grad[full])
        parts["tr"].append(tr)
        parts["rel"].append(rel)
        parts["t"].append(np.full(n, float(p.t_hq_us)))
        parts["pid"].append(np.full(n, pid))
        pid += 1
    if not parts["X"]:
        X = np.zeros((0, 3))
        return FeatureData(X, np.zeros((0, 2)), np.zeros((0, M, 2)), np.zeros((0, M)), np.zeros(0), np.zeros(0, int),
                           float(t0_us), K_lq, K_hq, T_hqcolor_hqdepth)
    X = np.concatenate(parts["X"])
    hq_xy = K_hq.project(T_hqcolor_hqdepth.apply(X))
    return FeatureData(X, hq_xy, np.concatenate(parts["tr"]), np.concatenate(parts["rel"]), np.concatenate(parts["t"]),
                       np.concatenate(parts["pid"]), float(t0_us), K_lq, K_hq, T_hqcolor_hqdepth,
                       np.concatenate(parts["g"]))


def interpolate_tracks(tracks: np.ndarray, stamps: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each track at its instant ``s`` ``(F,)``: positions ``(F, 2)`` linear between the samples around it
    (``stamps`` ``(F, M)`` increasing, ``inf`` padding), and whether ``s`` lies inside the samples."""
    F, M = stamps.shape
    k = np.clip((stamps <= s[:, None]).sum(axis=1) - 1, 0, M - 2)
    rows = np.arange(F)
    t1, t2 = stamps[rows, k], stamps[rows, k + 1]
    p1, p2 = tracks[rows, k], tracks[rows, k + 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        alpha = (s - t1) / (t2 - t1)
        pos = p1 + alpha[:, None] * (p2 - p1)
    inside = np.isfinite(t2) & (s >= stamps[:, 0]) & (s <= t2) & np.all(np.isfinite(pos), axis=1)
    return pos, inside


class FeatureModel:
    """Residuals of :class:`FeatureData` under the base model plus a set of effects.

    Args:
        data: the features. effects: :class:`align.loop.effects.Effect` objects (their order is
            the parameter order after ``pose`` and ``shift``).
    """

    def __init__(self, data: FeatureData, effects) -> None:
        self.data = data
        self.effects = list(effects)
        self.layout: dict[str, slice] = {"pose": slice(0, 6), "shift": slice(6, 7)}
        n = 7
        for e in self.effects:
            self.layout[e.name] = slice(n, n + len(e.params))
            n += len(e.params)
        self.n_params = n
        steps = [1e-5] * 3 + [1e-5] * 3 + [0.005]
        for e in self.effects:
            steps += list(e.steps)
        self.steps = np.asarray(steps)

    def names(self) -> list[str]:
        out = [f"pose.{k}" for k in ("rx", "ry", "rz", "tx", "ty", "tz")] + ["shift.a_ms"]
        for e in self.effects:
            out += [f"{e.name}.{p}" for p in e.params]
        return out

    def x0(self, T: Transform, shift_us: float, values: dict | None = None) -> np.ndarray:
        """Parameter vector for pose ``T``, shift ``shift_us`` and effect values (``{name: array}``; default neutral)."""
        x = np.zeros(self.n_params)
        x[:3], x[3:6], x[6] = T.rotvec(), T.t, shift_us / 1000.0
        for e in self.effects:
            x[self.layout[e.name]] = (values or {}).get(e.name, np.zeros(len(e.params)))
        return x

    def pose(self, x: np.ndarray) -> Transform:
        return Transform.from_rotvec(x[:3], x[3:6])

    def residuals(self, x: np.ndarray, *, data: FeatureData | None = None) -> np.ndarray:
        """``(2F,)`` pixel residuals at parameters ``x`` (0 where a feature's instant leaves its window)."""
        d = self.data if data is None else data
        pts = d.points
        K = d.K_lq
        s = np.full(len(d), x[6] * 1000.0)
        stamps = d.rel_us
        for e in self.effects:
            v = x[self.layout[e.name]]
            pts = e.correct_points(d, pts, v)
            s = s + e.time_offset_us(d, v)
            stamps = e.sample_offset_us(d, stamps, v)
            K = e.lq_camera(K, v)
        pred = K.project(self.pose(x).apply(pts))
        pos, inside = interpolate_tracks(d.tracks, stamps, s)
        r = pred - pos
        r[~(inside & np.all(np.isfinite(r), axis=1))] = 0.0
        return r.ravel()

    def jacobian(self, x: np.ndarray, *, columns=None, data: FeatureData | None = None) -> np.ndarray:
        """``(2F, n)`` central-difference Jacobian for the parameter indices ``columns`` (default all)."""
        cols = np.arange(self.n_params) if columns is None else np.asarray(columns)
        J = np.empty((2 * len(self.data if data is None else data), cols.size))
        for c, i in enumerate(cols):
            h = self.steps[i]
            xp, xm = x.copy(), x.copy()
            xp[i] += h
            xm[i] -= h
            J[:, c] = (self.residuals(xp, data=data) - self.residuals(xm, data=data)) / (2 * h)
        return J
