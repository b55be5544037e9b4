"""Synthetic probes for tests and studies of the loop: features of a moving scene seen by two cameras,
with the effects of the library switched on by formula (an independent reference: no renderer, no fit).
Pure numpy.

Scene time = HQ clock. HQ probe ``p`` at stamp ``t_p`` lifts ``N`` points; a moving point is
``X(t) = X + V (t - t_p)`` (HQ depth frame). The LQ frame stamped ``u`` (LQ clock) shows row ``y``
at HQ time ``tau`` with ``tau + Delta(tau) = u + r ((y + 0.5) / H - 0.5)``, ``Delta(t) = a + b (t - t0)``;
its pixel is ``pi_LQ(T X(tau))`` through LQ lens ``k1``. With an HQ colour lens ``hq_k1`` the HQ
keypoint is the distorted projection and the lifted point lies on the undistorted (declared) ray.
"""
from __future__ import annotations

import numpy as np

from align.loop.features import pack_probes
from align.time_shift import Probe
from capture.camera import Intrinsics, Transform

K_LQ = Intrinsics(320, 240, 300.0, 300.0, 159.5, 119.5)
K_HQ = Intrinsics(320, 240, 260.0, 260.0, 159.5, 119.5)
T_HQC_HQD = Transform.from_rotvec([0.0, 0.0, 0.0], [0.032, 0.0, 0.0])  # HQ colour <- HQ depth
T_TRUE = Transform.from_rotvec([0.01, -0.02, 0.005], [0.125, 0.01, -0.005])  # LQ colour <- HQ depth
T0_US = 1_700_000_000_000_000
PERIOD = 33_333


def _with_k1(K: Intrinsics, k1: float) -> Intrinsics:
    return K if not k1 else Intrinsics(K.width, K.height, K.fx, K.fy, K.cx, K.cy, "opencv", (k1, 0, 0, 0, 0))


def make_probes(*, seed: int = 0, seconds: float = 8.0, probes: int = 24, n: int = 160, a_us: float = -20_000.0,
                drift_ppm: float = 0.0, readout_ms: float = 0.0, k1: float = 0.0, hq_k1: float = 0.0,
                noise_px: float = 0.3, moving: float = 0.5, window: int = 5):
    """``(list of Probe, truth dict)``."""
    rng = np.random.default_rng(seed)
    K_lq = _with_k1(K_LQ, k1)
    K_hqd = _with_k1(K_HQ, hq_k1)
    b = drift_ppm * 1e-6
    out = []
    t_probe = T0_US + np.linspace(0.3, seconds - 0.3, probes) * 1e6
    lq_phase = float(rng.uniform(0, PERIOD))
    for p, tp in enumerate(t_probe):
        tp = int(tp)
        # points in the HQ colour frame, spread over the image and 1.5-4.5 m deep
        z = rng.uniform(1.5, 4.5, n)
        q = np.stack([rng.uniform(5, K_HQ.width - 6, n), rng.uniform(5, K_HQ.height - 6, n)], axis=1)
        nd = np.stack([(q[:, 0] - K_HQ.cx) / K_HQ.fx, (q[:, 1] - K_HQ.cy) / K_HQ.fy], axis=1)  # declared ray
        nt = K_hqd.undistort(nd) if hq_k1 else nd  # the true ray of the (distorted) keypoint
        Xc_true = np.concatenate([nt * z[:, None], z[:, None]], axis=1)
        Xc_lift = np.concatenate([nd * z[:, None], z[:, None]], axis=1)
        X_true = T_HQC_HQD.inverse().apply(Xc_true)
        X_lift = T_HQC_HQD.inverse().apply(Xc_lift)
        V = np.zeros((n, 3))
        mv = rng.random(n) < moving
        V[mv] = rng.normal(0, 1.0, (mv.sum(), 3)) * np.array([0.8, 0.4, 0.3]) * 1e-6  # m/us
        # LQ frames around t_p + Delta
        centre = tp + a_us + b * (tp - T0_US)
        j0 = int(np.floor((centre - T0_US - lq_phase) / PERIOD)) - window // 2
        u = (T0_US + lq_phase + PERIOD * np.arange(j0, j0 + window)).astype(np.int64)
        tracks = np.empty((window, n, 2))
        for m, uj in enumerate(u):
            y = np.full(n, K_LQ.height / 2)
            for _ in range(4):  # the row decides the instant, the instant the row
                off = readout_ms * 1e3 * ((y + 0.5) / K_LQ.height - 0.5)
                tau = (uj + off - a_us + b * T0_US) / (1 + b)  # tau + a + b (tau - t0) = u + off
                pix = K_lq.project(T_TRUE.apply(X_true + V * (tau - tp)[:, None]))
                y = pix[:, 1]
            tracks[m] = pix + rng.normal(0, noise_px, (n, 2))
        inside = np.all((tracks[..., 0] > 0) & (tracks[..., 0] < K_LQ.width - 1) & (tracks[..., 1] > 0)
                        & (tracks[..., 1] < K_LQ.height - 1), axis=0)
        tracks[:, ~inside] = np.nan
        out.append(Probe(p, tp, X_lift, np.arange(j0, j0 + window), u, tracks, window // 2))
    truth = {"a_us": a_us, "drift_ppm": drift_ppm, "readout_ms": readout_ms, "k1": k1, "hq_k1": hq_k1}
    return out, truth


def feature_data(**kw):
    probes, truth = make_probes(**kw)
    fd = pack_probes(probes, K_lq=K_LQ, K_hq=K_HQ, T_hqcolor_hqdepth=T_HQC_HQD, t0_us=T0_US)
    return fd, truth


def start(truth: dict, rng_seed: int = 1) -> tuple[Transform, float]:
    """A base-fit-like start: the true pose and shift, perturbed a little."""
    rng = np.random.default_rng(rng_seed)
    T = Transform.from_rotvec(T_TRUE.rotvec() + rng.normal(0, 2e-3, 3), T_TRUE.t + rng.normal(0, 3e-3, 3))
    return T, truth["a_us"] + float(rng.normal(0, 500))
