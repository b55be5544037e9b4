"""align.clustered: the sandwich's meat against a direct sum over clusters; a shared error against a direct refit;
its doctests."""
from __future__ import annotations

import doctest

import numpy as np

import align.clustered
from align.clustered import cluster_meat, shared_error, two_way_parts


def test_doctests():
    assert doctest.testmod(align.clustered).failed == 0


def test_cluster_meat_equals_a_direct_sum_over_clusters_in_any_label_order():
    rng = np.random.default_rng(5)
    s = rng.normal(size=(50, 3))
    labels = rng.choice([7, -2, 40, 3], size=50)
    B = np.zeros((3, 3))
    for g in np.unique(labels):
        S = s[labels == g].sum(axis=0)
        B += np.outer(S, S)
    assert np.allclose(cluster_meat(s, labels), B * 4 / 3)


def test_two_way_with_a_trivial_second_clustering_is_the_one_way_sandwich():
    rng = np.random.default_rng(6)
    s, A_inv = rng.normal(size=(40, 2)), np.linalg.inv(np.cov(rng.normal(size=(2, 9))) + np.eye(2))
    a = rng.integers(0, 5, 40)
    Va, Vb, Vab = two_way_parts(A_inv, s, a, np.arange(40))
    assert np.allclose(Va + Vb - Vab, Va)


def test_shared_error_moves_the_others_as_a_refit_with_that_parameter_held_off():
    """A least-squares fit with parameter 1 held ``delta`` off its estimate and the others refitted moves them by
    ``g delta``; :func:`shared_error` is ``g g^T sd^2`` for that ``g`` (and adds nothing for a zero ``sd``)."""
    rng = np.random.default_rng(7)
    J = rng.normal(size=(60, 4)) @ (np.eye(4) + 0.6 * rng.normal(size=(4, 4)))  # correlated columns
    y = rng.normal(size=60)
    x = np.linalg.lstsq(J, y, rcond=None)[0]
    delta, others = 0.3, [0, 2, 3]
    z = np.linalg.lstsq(J[:, others], y - J[:, 1] * (x[1] + delta), rcond=None)[0]
    moved = np.insert(z - x[others], 1, delta)
    g = moved / delta
    A_inv = np.linalg.inv(J.T @ J)
    assert np.allclose(shared_error(A_inv, np.array([0.0, 0.5, 0.0, 0.0])), np.outer(g, g) * 0.25)
    assert np.allclose(shared_error(A_inv, np.zeros(4)), 0.0)
