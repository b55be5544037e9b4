"""The extrinsic fit's reported covariance against the spread of its estimates over repeated simulations (the truth
is known): keypoints seen again in every probe frame, each with its own placement error that repeats, are not
independent observations; the cluster-robust covariance covers the true pose about as often as it claims, the
Gauss-Newton one that counts every pair as independent does not."""
from __future__ import annotations

import numpy as np

from align.extrinsics import _pose_params, cluster_covariance, fit_extrinsics
from capture.camera import Intrinsics, Transform

K = Intrinsics(320, 240, fx=300.0, fy=300.0, cx=159.5, cy=119.5)
T_TRUE = Transform.from_rotvec(np.radians([0.5, -1.0, 0.3]), [0.05, -0.01, 0.02])


def _session(rng, *, keypoints=60, probes=12, persistent_px=0.3, fresh_px=0.1):
    """The same keypoints (a wall at 4-6 m and people at 1.5-3 m) in every probe; each keypoint's placement error
    is drawn once and repeats in every probe, plus a fresh error per observation."""
    far = np.column_stack([rng.uniform(-2.5, 2.5, keypoints // 2), rng.uniform(-1.8, 1.8, keypoints // 2),
                           rng.uniform(4, 6, keypoints // 2)])
    near = np.column_stack([rng.uniform(-0.8, 0.8, keypoints // 2), rng.uniform(-0.6, 0.6, keypoints // 2),
                            rng.uniform(1.5, 3, keypoints // 2)])
    X = np.concatenate([far, near])
    bias = rng.normal(0, persistent_px, X.shape[:1] + (2,))
    P = np.tile(X, (probes, 1))
    px = K.project(T_TRUE.apply(P)) + np.tile(bias, (probes, 1)) + rng.normal(0, fresh_px, P.shape[:1] + (2,))
    clusters = np.stack([np.repeat(np.arange(probes), len(X)), np.tile(np.arange(len(X)), probes)], axis=1)
    return P, px, clusters


def test_cluster_robust_intervals_cover_the_true_pose_the_independent_ones_do_not():
    rng = np.random.default_rng(7)
    x_true = _pose_params(T_TRUE)
    z_cluster, z_naive, spread = [], [], []
    for _ in range(120):
        P, px, cl = _session(rng)
        fit = fit_extrinsics(P, px, K, T_init=T_TRUE, clusters=cl)
        naive = fit_extrinsics(P, px, K, T_init=T_TRUE)
        assert np.array_equal(fit.T.matrix, naive.T.matrix)    # the clusters change the covariance only
        d = _pose_params(fit.T) - x_true
        spread.append(d)
        z_cluster.append(d / np.sqrt(np.diag(fit.covariance)))
        z_naive.append(d / np.sqrt(np.diag(naive.covariance)))
    cover = (np.abs(np.array(z_cluster)) < 1.96).mean()
    cover_naive = (np.abs(np.array(z_naive)) < 1.96).mean()
    assert 0.88 < cover < 0.99, cover
    assert cover_naive < 0.6, cover_naive
    # and the reported sd is the estimates' own spread (Monte Carlo), within 25 %
    ratio = np.std(spread, axis=0) / np.sqrt(np.mean(np.array(spread) ** 2 / np.array(z_cluster) ** 2, axis=0))
    assert np.all(np.abs(ratio - 1) < 0.25), ratio


def test_one_cluster_per_pair_is_the_independent_covariance():
    """With every pair its own cluster and small residuals (unit weights) the sandwich is White's
    heteroskedasticity-robust covariance: for homoskedastic noise, the Gauss-Newton one within sampling error."""
    rng = np.random.default_rng(3)
    P, px, _ = _session(rng, keypoints=200, probes=2, persistent_px=0.0, fresh_px=0.2)
    naive = fit_extrinsics(P, px, K, T_init=T_TRUE)
    iid = cluster_covariance(P[naive.inliers], px[naive.inliers], K, naive.T, np.arange(int(naive.inliers.sum())))
    ratio = np.sqrt(np.diag(iid) / np.diag(naive.covariance))
    assert np.all(np.abs(ratio - 1) < 0.15), ratio
