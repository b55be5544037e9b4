"""Cluster-robust ("sandwich") covariances, shared by the extrinsic fit and the effect loop.

Pure numpy, no I/O.

A least-squares or M-estimate ``x`` with Jacobian ``J`` has the covariance ``A^-1 B A^-1``: ``A`` the
fit's Hessian (``J^T W J``), ``B`` the spread of its scores ``s_i = J_i^T w_i r_i``. Counting every
row as independent, ``B = sum_i s_i s_i^T``. The alignment's rows are not independent: the features
of one probe frame share its timing and tracking, and a static scene shows the same keypoints, with
the same placement errors, to every probe. With rows correlated in any way inside a cluster and
independent between clusters, ``B = G / (G - 1) sum_c S_c S_c^T`` over the clusters' summed scores
``S_c`` (:func:`cluster_meat`). Two crossed clusterings (probe, and cell of the HQ image) combine as
``V_a + V_b - V_ab``, ``V_ab`` over their intersections (Cameron, Gelbach and Miller 2011,
:func:`two_way_parts`); that difference need not be positive definite, and each caller decides what to
do where it is not.

An error that every row shares (a session-wide offset of the time shift: ``align.time_shift.MODEL_ERROR_US``)
is invisible to any clustering within the session. Given its size ``sd_j`` on parameter ``j``, it reaches the
others as the fit would carry it: held ``delta`` off its estimate, parameter ``j`` moves the others, refitted, by
``g_j delta`` with ``g_j = Sigma[:, j] / Sigma[j, j]`` (``Sigma = A^-1``: the regression of the others on it), so
the covariance gains ``sum_j g_j g_j^T sd_j^2`` (:func:`shared_error`).

Users: :func:`align.extrinsics.cluster_covariance` (the extrinsic fit, ``fit_extrinsics(clusters=...)``)
and :mod:`align.loop.loop` (``sandwich``, ``sandwich_two_way``: the effect loop's IRLS fits). Both cut
the HQ image into the same grid of cells (:func:`grid_cells`).

>>> s = np.array([[1.0], [1.0], [-1.0], [3.0]])          # scores of four rows, one parameter
>>> float(cluster_meat(s, np.array([0, 0, 1, 1]))[0, 0])  # clusters {0, 1}: (1 + 1)^2 + (-1 + 3)^2, times 2/1
16.0
>>> float(cluster_meat(s, np.arange(4))[0, 0])            # every row its own cluster: 12 * 4/3
16.0
>>> shared_error(np.array([[4.0, 2.0], [2.0, 3.0]]), np.array([0.5, 0.0])).tolist()  # g = (1, 0.5)
[[0.25, 0.125], [0.125, 0.0625]]
>>> grid_cells(np.array([0.0, 639.0, np.nan]), np.array([0.0, 479.0, 10.0]), width=640, height=480, cells=8).tolist()
[0, 63, -1]
"""
from __future__ import annotations

import numpy as np


def cluster_meat(scores: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """``(k, k)``: ``G / (G - 1) sum_c S_c S_c^T`` over the ``G`` clusters of ``labels`` ``(n,)`` (any integers,
    any order), ``S_c`` the sum of the rows of ``scores`` ``(n, k)`` in cluster ``c`` (summed in row order)."""
    order = np.argsort(labels, kind="stable")
    lab = np.asarray(labels)[order]
    starts = np.flatnonzero(np.r_[True, lab[1:] != lab[:-1]]) if lab.size else np.zeros(0, int)
    S = np.add.reduceat(np.asarray(scores)[order], starts, axis=0) if lab.size else np.zeros((0, scores.shape[1]))
    G = S.shape[0]
    return S.T @ S * (G / max(G - 1, 1))


def sandwich(A_inv: np.ndarray, scores: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """``A^-1 B A^-1`` with ``B`` :func:`cluster_meat` of ``scores`` over ``labels``."""
    return A_inv @ cluster_meat(scores, labels) @ A_inv


def two_way_parts(A_inv: np.ndarray, scores: np.ndarray, labels_a: np.ndarray,
                  labels_b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(V_a, V_b, V_ab)``: the sandwich over each clustering and over their intersections; the two-way
    covariance is ``V_a + V_b - V_ab`` (module docstring)."""
    both = np.unique(np.stack([labels_a, labels_b], axis=1), axis=0, return_inverse=True)[1].reshape(-1)
    return tuple(sandwich(A_inv, scores, g) for g in (labels_a, labels_b, both))


def shared_error(A_inv: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """``(k, k)``: the covariance that errors shared by every row add to a fit's parameters, ``sd`` ``(k,)`` each
    parameter's shared error (0: none), carried into the others through ``A_inv`` (the fit's inverse Hessian):
    ``sum_j g_j g_j^T sd_j^2``, ``g_j = A_inv[:, j] / A_inv[j, j]`` (module docstring)."""
    sd = np.asarray(sd, np.float64)
    j = np.flatnonzero(sd)
    G = A_inv[:, j] / np.diag(A_inv)[j]
    return (G * sd[j] ** 2) @ G.T


def grid_cells(x: np.ndarray, y: np.ndarray, *, width: int, height: int, cells: int) -> np.ndarray:
    """``(n,)`` int64: the cell of a ``cells x cells`` grid over a ``width x height`` image that each point
    ``(x, y)`` (pixels) lies in, row-major; ``-1`` where a coordinate is NaN."""
    cx = np.clip(x * cells // width, 0, cells - 1)
    cy = np.clip(y * cells // height, 0, cells - 1)
    return np.nan_to_num(cy * cells + cx, nan=-1).astype(np.int64)
