"""align.clustered: the sandwich's meat against a direct sum over clusters; its doctests."""
from __future__ import annotations

import doctest

import numpy as np

import align.clustered
from align.clustered import cluster_meat, two_way_parts


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
