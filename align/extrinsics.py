"""Extrinsic fit from 3D-2D correspondences (seed report eq. 30-31) and rig composition.

Pure numpy/OpenCV/scipy, no I/O.

Eq. 30 maps an HQ point into the LQ image, ``p~ = pi_LQ(T_ex * pi_HQ^-1(p_HQ))``; eq. 31 sums
``||p~ - p_LQ||_2`` over the matched feature pairs ``U``. :func:`fit_extrinsics` minimises it in
two steps:

1. a robust initialisation, PnP with RANSAC (``cv2.solvePnPRansac``) on all pairs at once;
2. a robust refinement of the 6 pose parameters (rotation vector, translation) on all pairs of
   all retained frames jointly with ``scipy.optimize.least_squares`` and a robust loss
   (``soft_l1`` by default, scale in pixels), which keeps the eq. 31 reprojection residual as
   its residual vector.

The pipeline (:func:`align.pipeline.fit_pair`) fits twice: between the two fits it moves every LQ
keypoint to where its HQ colour patch lies in the LQ image (:func:`align.features.refine_offsets`).
SIFT's own placement differs by ~0.45 px (median) between the two cameras and repeats every frame on
still texture; the translation along the optical axis, which reprojection constrains weakly (a
magnification of ``t_z / Z``), took it up: +1.12 mm [0.87, 1.41] in z over 10 clean sessions, -0.08
[-0.21, +0.05] after (session 9 notes, ``extr``).

Uncertainty. The pipeline's correspondences are not independent: the same still keypoints recur in all 24
probes with the same placement error, and the pairs of a probe share its timing. Given cluster labels
(:func:`align.pipeline.fit_clusters`: probe, and cell of the HQ image), :func:`fit_extrinsics` reports the
cluster-robust covariance (:func:`cluster_covariance`) instead of the Gauss-Newton one; the pipeline then adds the
time shift's variance carried through the fit (:func:`align.pipeline.with_shift_uncertainty`: people walk
sideways, so a shift error moves ``t_x`` by 1-1.4 mm per ms). On 26 held-out simulated sessions the 95 %
intervals (+-1.96 sd) then held the simulator's pose on 23-26 of 26 per axis (Gauss-Newton: 5-19 of 26; session 10,
``tidy`` notes); the pose itself is the same either way.

Multi-view rigs: :func:`compose_rig` expresses pairwise fits in one rig frame and reports the
loop-closure error of redundant pairs.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import least_squares

from align.clustered import sandwich, two_way_parts
from align.errors import FeatureError
from capture.camera import Intrinsics, Transform

#: fewest correspondences a fit accepts
MIN_POINTS = 12


def reproject(points: np.ndarray, T_cam_obj: Transform, K: Intrinsics) -> np.ndarray:
    """Eq. 30: points ``(N, 3)`` (object frame, metres) to pixels ``(N, 2)`` of camera ``K``."""
    return K.project(T_cam_obj.apply(points))


def reprojection_errors(points: np.ndarray, pixels: np.ndarray, T_cam_obj: Transform, K: Intrinsics) -> np.ndarray:
    """Eq. 31 terms: ``||pi(T X) - p||_2`` per pair, ``(N,)`` pixels (NaN behind the camera)."""
    return np.linalg.norm(reproject(points, T_cam_obj, K) - np.asarray(pixels, np.float64), axis=1)


@dataclass
class ExtrinsicFit:
    """Result of :func:`fit_extrinsics`.

    Attributes:
        T: the fitted ``T_cam_obj`` (e.g. LQ colour camera <- HQ depth camera).
        inliers: ``(N,)`` bool, pairs within ``inlier_px`` after refinement.
        residuals_px: ``(N,)`` eq. 31 terms after refinement.
        n_pairs, n_inliers: counts. rms_px, median_px: of the inliers.
        cost_history: eq. 31 mean robust cost after initialisation and after refinement.
        covariance: ``(6, 6)`` covariance of (rotation vector rad, translation m): without cluster labels the
            inliers' Gauss-Newton one (normal matrix scaled by their residual variance, every pair independent);
            with them the cluster-robust one (:func:`cluster_covariance`), and in the pipeline plus the time
            shift's part (:func:`align.pipeline.with_shift_uncertainty`).
        covariance_fit: the fit's own covariance where the pipeline added the time shift's, else None.
    """

    T: Transform
    inliers: np.ndarray
    residuals_px: np.ndarray
    n_pairs: int
    n_inliers: int
    rms_px: float
    median_px: float
    covariance: np.ndarray = field(default_factory=lambda: np.full((6, 6), np.nan))
    init_inliers: int = 0
    covariance_fit: np.ndarray | None = None

    @property
    def rotation_std_deg(self) -> float:
        return pose_std(self.covariance)[1]

    @property
    def translation_std_m(self) -> float:
        return pose_std(self.covariance)[0]

    def summary(self) -> dict:
        return {"pairs": self.n_pairs, "inliers": self.n_inliers, "rms_px": self.rms_px, "median_px": self.median_px,
                "rotation_std_deg": self.rotation_std_deg, "translation_std_mm": 1e3 * self.translation_std_m}


def pose_std(covariance: np.ndarray) -> tuple[float, float]:
    """``(translation m, rotation deg)``: the root of the trace of a pose covariance's translation and rotation
    blocks (``(6, 6)`` over rotation vector rad and translation m, or any larger one with those first).

    >>> pose_std(np.diag([1e-4, 0, 0, 9e-6, 0, 16e-6]))
    (0.005, 0.5729577951308232)
    """
    return (float(np.sqrt(max(np.trace(covariance[3:6, 3:6]), 0.0))),
            float(np.degrees(np.sqrt(max(np.trace(covariance[:3, :3]), 0.0)))))


def _pose_params(T: Transform) -> np.ndarray:
    return np.concatenate([T.rotvec(), T.t])


def _pose(x: np.ndarray) -> Transform:
    return Transform.from_rotvec(x[:3], x[3:])


def pnp_ransac(points: np.ndarray, pixels: np.ndarray, K: Intrinsics, *, reprojection_px: float = 2.0,
               iterations: int = 2000, confidence: float = 0.999, seed: int = 0) -> tuple[Transform, np.ndarray]:
    """Robust initial pose: ``cv2.solvePnPRansac`` (EPnP minimal sets, then iterative on the inliers).

    Returns ``(T_cam_obj, inlier mask)``. Raises :class:`FeatureError` when no pose is found.
    """
    P = np.ascontiguousarray(points, np.float64).reshape(-1, 1, 3)
    p = np.ascontiguousarray(pixels, np.float64).reshape(-1, 1, 2)
    if P.shape[0] < MIN_POINTS:
        raise FeatureError(f"only {P.shape[0]} 3D-2D feature pairs, need at least {MIN_POINTS} for the extrinsic fit")
    cv2.setRNGSeed(seed)
    ok, rvec, tvec, inl = cv2.solvePnPRansac(P, p, K.K, K.dist_coeffs, iterationsCount=iterations,
                                             reprojectionError=reprojection_px, confidence=confidence,
                                             flags=cv2.SOLVEPNP_EPNP)
    if not ok or inl is None or len(inl) < MIN_POINTS:
        n = 0 if inl is None else len(inl)
        raise FeatureError(f"PnP found no consistent pose ({n} of {P.shape[0]} feature pairs agree within "
                           f"{reprojection_px} px): too few or wrong matches")
    mask = np.zeros(P.shape[0], bool)
    mask[inl.ravel()] = True
    ok, rvec, tvec = cv2.solvePnP(P[mask], p[mask], K.K, K.dist_coeffs, rvec, tvec, useExtrinsicGuess=True,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    T = Transform.from_rotvec(rvec.ravel(), tvec.ravel())
    return T, mask


def refine_extrinsics(points: np.ndarray, pixels: np.ndarray, K: Intrinsics, T0: Transform, *, loss: str = "soft_l1",
                      scale_px: float = 1.0, weights: np.ndarray | None = None, max_nfev: int = 200):
    """Robust joint least squares of eq. 31 over all pairs: returns ``(T, result)``.

    ``weights`` ``(N,)`` multiplies each pair's residual (e.g. 0 for pairs excluded upstream).
    """
    P = np.asarray(points, np.float64)
    p = np.asarray(pixels, np.float64)
    wts = np.ones(P.shape[0]) if weights is None else np.asarray(weights, np.float64)

    def fun(x):
        r = (reproject(P, _pose(x), K) - p) * wts[:, None]
        return np.nan_to_num(r, nan=1e3).ravel()

    res = least_squares(fun, _pose_params(T0), loss=loss, f_scale=scale_px, method="trf", x_scale="jac",
                        max_nfev=max_nfev)
    return _pose(res.x), res


def fit_extrinsics(points: np.ndarray, pixels: np.ndarray, K: Intrinsics, *, T_init: Transform | None = None,
                   ransac_px: float = 2.0, inlier_px: float = 2.0, loss: str = "soft_l1", scale_px: float = 1.0,
                   seed: int = 0, clusters: np.ndarray | None = None) -> ExtrinsicFit:
    """Eq. 30-31: ``T_cam_obj`` that puts 3D points ``(N, 3)`` (object frame) on their pixels ``(N, 2)``.

    PnP + RANSAC initialisation (or ``T_init``), robust refinement on all pairs, a second
    refinement on the inliers of the first; residuals, inliers and the pose covariance returned.
    ``clusters``: ``(N,)`` or ``(N, k)`` integer labels of pairs whose errors are correlated (:func:`cluster_covariance`);
    the covariance is then cluster-robust (the pose itself does not change), else it treats every pair as independent.
    """
    P = np.asarray(points, np.float64).reshape(-1, 3)
    p = np.asarray(pixels, np.float64).reshape(-1, 2)
    good = np.all(np.isfinite(P), axis=1) & np.all(np.isfinite(p), axis=1)
    P, p = P[good], p[good]
    groups = None if clusters is None else np.asarray(clusters).reshape(good.shape[0], -1)[good]
    if P.shape[0] < MIN_POINTS:
        raise FeatureError(f"only {P.shape[0]} 3D-2D feature pairs, need at least {MIN_POINTS} for the extrinsic fit")
    if T_init is None:
        T0, mask0 = pnp_ransac(P, p, K, reprojection_px=ransac_px, seed=seed)
    else:
        T0 = T_init
        mask0 = reprojection_errors(P, p, T0, K) < max(ransac_px, inlier_px) * 4
    T1, _ = refine_extrinsics(P, p, K, T0, loss=loss, scale_px=scale_px)
    inl = reprojection_errors(P, p, T1, K) < inlier_px * 2
    if inl.sum() < MIN_POINTS:
        raise FeatureError(f"only {int(inl.sum())} of {P.shape[0]} feature pairs fit one pose within {2 * inlier_px} px")
    T, res = refine_extrinsics(P[inl], p[inl], K, T1, loss=loss, scale_px=scale_px)
    err = reprojection_errors(P, p, T, K)
    inliers = err < inlier_px
    cov = _covariance(res, inliers[inl])
    if groups is not None:   # the independent one stays where the clusters cannot give a positive definite one
        robust = cluster_covariance(P[inliers], p[inliers], K, T, groups[inliers], loss=loss, scale_px=scale_px)
        cov = robust if np.all(np.isfinite(robust)) else cov
    full_err = np.full(good.shape[0], np.nan)
    full_err[good] = err
    full_in = np.zeros(good.shape[0], bool)
    full_in[good] = inliers
    e_in = err[inliers]
    return ExtrinsicFit(T=T, inliers=full_in, residuals_px=full_err, n_pairs=int(good.sum()),
                        n_inliers=int(inliers.sum()),
                        rms_px=float(np.sqrt(np.mean(e_in ** 2))) if e_in.size else float("nan"),
                        median_px=float(np.median(e_in)) if e_in.size else float("nan"), covariance=cov,
                        init_inliers=int(mask0.sum()))


def _covariance(res, inlier_rows: np.ndarray) -> np.ndarray:
    """Pose covariance from the Jacobian at the solution: sigma^2 (J^T J)^-1 over the inlier rows."""
    J = res.jac
    rows = np.repeat(inlier_rows, 2)
    J = J[rows]
    r = res.fun[rows]
    if J.shape[0] <= 6:
        return np.full((6, 6), np.nan)
    sigma2 = float(r @ r) / (J.shape[0] - 6)
    try:
        return sigma2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return np.full((6, 6), np.nan)


def _raw_jacobian(P: np.ndarray, T: Transform, K: Intrinsics, h: float = 1e-7) -> np.ndarray:
    """``(2N, 6)`` d(reprojection)/d(rotation vector, translation) at ``T``, central differences."""
    x0 = _pose_params(T)
    J = np.empty((2 * P.shape[0], 6))
    for k in range(6):
        d = np.zeros(6)
        d[k] = h
        J[:, k] = (reproject(P, _pose(x0 + d), K) - reproject(P, _pose(x0 - d), K)).ravel() / (2 * h)
    return J


def cluster_covariance(points: np.ndarray, pixels: np.ndarray, K: Intrinsics, T: Transform, clusters: np.ndarray, *,
                       loss: str = "soft_l1", scale_px: float = 1.0) -> np.ndarray:
    """Cluster-robust (sandwich) covariance of the pose that minimises eq. 31 over ``points``/``pixels``.

    The Gauss-Newton covariance ``sigma^2 (J^T J)^-1`` counts every pair as an independent observation. The
    pipeline's pairs are not: still texture shows the same keypoints to every probe frame, and a keypoint's
    placement error (SIFT's, then the patch refinement's ~0.2 px of aliasing) repeats in each; the pairs of one
    probe share its frame's timing. The fit is an M-estimate of the robust ``loss`` ``c^2 rho((r / c)^2)`` per
    residual (``linear``: ``rho(z) = z``; ``soft_l1``: ``2 (sqrt(1 + z) - 1)``), and its covariance the sandwich
    ``A^-1 B A^-1``: ``A = J^T diag(rho'(z) + 2 z rho''(z)) J`` (the loss's Hessian; ``(1 + z)^-3/2`` for
    ``soft_l1``), ``B = sum over clusters of s_c s_c^T`` with the clusters' summed scores ``s_c = (J^T rho'(z) r)_c``
    (times ``G / (G - 1)``; :mod:`align.clustered`): errors may be correlated in any way within a cluster, independent between clusters.
    ``clusters`` ``(N,)`` labels (one way) or ``(N, 2)`` (two ways: ``V_a + V_b - V_ab`` over the intersections,
    Cameron, Gelbach and Miller 2011; where that is not positive definite, e.g. with fewer probes than pose
    parameters, the conservative ``V_a + V_b``). With one cluster per pair and the linear
    loss it is White's heteroskedasticity-robust covariance, for equal noise close to ``sigma^2 (J^T J)^-1``.
    Returns ``(6, 6)`` for (rotation vector rad, translation m); NaN where ``A`` is singular or no positive definite
    covariance results.
    """
    if loss not in ("linear", "soft_l1"):
        raise ValueError(f"cluster_covariance: loss must be linear or soft_l1, got {loss!r}")
    P = np.asarray(points, np.float64).reshape(-1, 3)
    r = (reproject(P, T, K) - np.asarray(pixels, np.float64).reshape(-1, 2)).ravel()
    J = _raw_jacobian(P, T, K)
    z = (r / scale_px) ** 2
    w_score, w_hess = (np.ones_like(z), np.ones_like(z)) if loss == "linear" else ((1 + z) ** -0.5, (1 + z) ** -1.5)
    try:
        A_inv = np.linalg.inv((J * w_hess[:, None]).T @ J)
    except np.linalg.LinAlgError:
        return np.full((6, 6), np.nan)
    s = J * (w_score * r)[:, None]
    lab = np.repeat(np.asarray(clusters).reshape(P.shape[0], -1), 2, axis=0)   # both rows of a pair
    if lab.shape[1] == 1:
        candidates = [sandwich(A_inv, s, lab[:, 0])]
    else:
        Va, Vb, Vab = two_way_parts(A_inv, s, lab[:, 0], lab[:, 1])
        candidates = [Va + Vb - Vab, Va + Vb]
    for V in candidates:
        V = 0.5 * (V + V.T)
        if np.linalg.eigvalsh(V).min() > 0:
            return V
    return np.full((6, 6), np.nan)


# --------------------------------------------------------------------------- multi-view rigs
@dataclass
class RigCalibration:
    """Extrinsics of every sensor in one rig frame (the reference sensor's depth camera).

    ``T_rig_sensor[s]`` maps points of sensor ``s``'s depth camera into the rig frame;
    ``loop_errors`` lists redundant pairs ``(a, b, translation m, rotation deg)`` comparing a
    direct fit of ``T_a_b`` with the composition through the rig frame. After the joint
    refinement (:mod:`align.rig_refine`): ``std[s]`` = (translation m, rotation deg) sds of
    ``T_rig_sensor[s]``, ``refinement`` its summary (pairs, loop check, feature fits' offsets,
    warnings) and ``T_rig_sensor_features`` the feature rig it started from.
    """

    reference: str
    T_rig_sensor: dict[str, Transform]
    loop_errors: list[tuple[str, str, float, float]] = field(default_factory=list)
    std: dict[str, tuple[float, float]] = field(default_factory=dict)
    refinement: dict | None = None
    T_rig_sensor_features: dict[str, Transform] | None = None

    @property
    def warnings(self) -> list[str]:
        return list((self.refinement or {}).get("warnings", []))

    def T_dst_src(self, dst: str, src: str) -> Transform:
        return self.T_rig_sensor[dst].inverse() @ self.T_rig_sensor[src]

    def to_dict(self) -> dict:
        return {"reference": self.reference,
                "T_rig_sensor": {s: T.to_list() for s, T in self.T_rig_sensor.items()},
                "loop_errors": [{"a": a, "b": b, "translation_mm": 1e3 * t, "rotation_deg": r}
                                for a, b, t, r in self.loop_errors],
                **({"T_rig_sensor_std": {s: {"translation_mm": 1e3 * t, "rotation_deg": r} for s, (t, r) in self.std.items()}}
                   if self.std else {}),
                **({"T_rig_sensor_features": {s: T.to_list() for s, T in self.T_rig_sensor_features.items()}}
                   if self.T_rig_sensor_features else {}),
                **({"refinement": self.refinement} if self.refinement is not None else {})}


def compose_rig(reference: str, T_ref_sensor: dict[str, Transform],
                direct: dict[tuple[str, str], Transform] | None = None) -> RigCalibration:
    """Rig frame = ``reference``'s depth camera; ``T_ref_sensor[s]`` from pairwise fits against it.

    ``direct`` holds extra fits ``T_a_b`` between non-reference sensors; each is compared with
    ``T_ref_a^-1 T_ref_b`` (the loop-closure error says how consistent the rig is).
    """
    T = {reference: Transform.identity(), **{s: t for s, t in T_ref_sensor.items() if s != reference}}
    loops = []
    for (a, b), T_ab in (direct or {}).items():
        composed = T[a].inverse() @ T[b]
        dt, dr = T_ab.error_to(composed)
        loops.append((a, b, dt, dr))
    return RigCalibration(reference, T, loops)
