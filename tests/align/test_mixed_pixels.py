"""HQ time-of-flight mixed samples (align.mixed_pixels) and the ``mixed`` edge rule: the test against a
direct loop of its rules, the noise estimate against a known noise, and the rule against an analytic
ray-cast truth on a scene whose HQ depth carries the simulator's mixed pixels."""
import numpy as np
import pytest

from align.mixed_pixels import MIN_RELATIVE_NOISE, mixed_samples, nearest_around, relative_noise
from align.reference_edges import EdgeRule
from align.warp import DepthWarper
from tests.align.scene import cast, room
from tests.align.test_reference_edges import _mixed_pixels
from tests.align.test_warp import _rig


def _mixed_loop(z, rel, k, s):
    """The module docstring's two kinds, one sample at a time, in float64."""
    H, W = z.shape

    def w(i, j):
        return 1 / float(z[i, j]) if 0 <= i < H and 0 <= j < W and np.isfinite(z[i, j]) else None

    def same(a, b):
        return a is not None and b is not None and abs(a - b) <= rel * min(a, b)

    out = np.zeros((H, W), bool)
    for i in range(H):
        for j in range(W):
            w0 = w(i, j)
            if w0 is None:
                continue
            for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
                w1, w2, w3 = (w(i - n * dy, j - n * dx) for n in (1, 2, 3))
                if not (same(w0, w1) and same(w1, w2)) or same(w0, w(i + dy, j + dx)):
                    continue
                if same(w2, w3):
                    pred, sd = (4 * w1 + w2 - 2 * w3) / 3, np.sqrt(1 + 7 / 3) * s
                else:
                    pred, sd = 2 * w1 - w2, np.sqrt(6) * s
                out[i, j] |= abs(w0 - pred) > k * sd * w0
            for dy, dx in ((0, 1), (1, 0)):
                out[i, j] |= not same(w0, w(i - dy, j - dx)) and not same(w0, w(i + dy, j + dx))
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_mixed_samples_equal_a_direct_loop(seed):
    rng = np.random.default_rng(seed)
    # slanted surfaces at two depths, edges between them, mixes and holes along the edges
    y, x = np.mgrid[0:18, 0:23]
    z = np.where((x - 11) ** 2 + (y - 9) ** 2 < 30, 2.0 + 0.01 * x, 4.0 + 0.02 * y).astype(np.float32)
    z *= (1 + 0.002 * rng.standard_normal(z.shape)).astype(np.float32)
    z = _mixed_pixels(z, rng, jump_m=0.5)
    z[rng.random(z.shape) < 0.05] = np.nan
    got = mixed_samples(z, edge_rel=0.03, k_sigma=3.0, sigma=0.002)
    want = _mixed_loop(z, 0.03, 3.0, 0.002)
    assert got.any() and not got.all()
    assert np.array_equal(got, want)


def test_relative_noise_is_that_of_the_depth():
    rng = np.random.default_rng(5)
    y, x = np.mgrid[0:120, 0:160]
    plane = (2.5 + 0.004 * x + 0.002 * y + 1.5 * (x >= 80)).astype(np.float32)  # an edge: its steps not counted
    for rel in (0.001, 0.004):
        z = (plane * (1 + rel * rng.standard_normal(plane.shape))).astype(np.float32)
        assert relative_noise(z) == pytest.approx(rel, rel=0.1)
    assert relative_noise(plane) == MIN_RELATIVE_NOISE  # noise-free input: the floor
    assert relative_noise(np.full((4, 4), np.nan, np.float32)) == MIN_RELATIVE_NOISE  # too few samples


def test_nearest_around():
    z = np.array([[2.0, np.nan, 3.0], [4.0, 5.0, 6.0]], np.float32)
    assert nearest_around(z).tolist() == [[2.0, 2.0, 3.0], [2.0, 2.0, 3.0]]


def test_mixed_rule_removes_whole_jump_errors_the_strict_rule_leaves():
    # analytic truth on both cameras (HQ 12.5 cm beside LQ, LQ 1.6x finer, half scale), HQ with the
    # simulator's mixed pixels and 0.1 % noise
    Kh, Kl, T_lq_hq, T_hq_world, T_lq_world = _rig(scale=0.5, distortion=False)
    acc = {}
    for s, person in enumerate(((0.0, 0.2, 2.2), (-0.4, 0.1, 1.8), (0.5, 0.3, 2.6))):
        shapes = room(person_at=person)
        rng = np.random.default_rng(s)
        dh = _mixed_pixels(cast(Kh, T_hq_world, shapes)[0], rng)
        dh = (dh * (1 + 0.001 * rng.standard_normal(dh.shape))).astype(np.float32)
        dl = cast(Kl, T_lq_world, shapes)[0]
        for name in ("strict", "mixed"):
            rule = EdgeRule.named(name)
            ref, at_warp = rule.warp(DepthWarper(Kh, Kl, T_lq_hq, edge_reach=rule.edge_reach), dh)
            ref, mask = rule.apply(ref)
            if at_warp is not None:
                mask |= at_warp
            e = np.abs(ref - dl)[np.isfinite(ref) & np.isfinite(dl)]
            a = acc.setdefault(name, np.zeros(5))
            a += (int((e > 0.3).sum()), e.sum(), (e ** 2).sum(), e.size, int((mask & np.isfinite(dl)).sum()))
    n_truth = acc["strict"][3]
    gross = {k: a[0] for k, a in acc.items()}
    rmse = {k: np.sqrt(a[2] / a[3]) for k, a in acc.items()}
    assert gross["strict"] >= 5  # the strict rule's whole-jump errors exist on this scene
    assert gross["mixed"] <= 0.4 * gross["strict"]
    assert rmse["mixed"] < 0.7 * rmse["strict"]
    assert acc["mixed"][4] < 0.07 * n_truth  # the mask stays a band


def test_pair_references_count_what_the_mixed_rule_masks_and_keep_strict_bit_for_bit():
    from align.pair_reference import PairReferences, ReferenceOptions

    Kh, Kl, T_lq_hq, T_hq_world, T_lq_world = _rig(scale=0.5, distortion=False)
    rng = np.random.default_rng(3)
    dh = _mixed_pixels(cast(Kh, T_hq_world, room(person_at=(0.0, 0.2, 2.2)))[0], rng)
    dh = (dh * (1 + 0.001 * rng.standard_normal(dh.shape))).astype(np.float32)
    plain = DepthWarper(Kh, Kl, T_lq_hq, edge_reach=0.0)(dh)
    refs = {name: PairReferences(lambda i: dh, K_hq=Kh, K_lq=Kl, T_lq_hq=T_lq_hq, t_hq_us=np.array([0]),
                                 options=ReferenceOptions(reference_edges=name, motion=False))(0, 0.0)
            for name in ("strict", "mixed")}
    strict, mask = EdgeRule.named("strict").apply(plain)
    assert np.array_equal(refs["strict"].depth, strict, equal_nan=True) and np.array_equal(refs["strict"].edge_mask, mask)
    m = refs["mixed"]
    # masked: the plain warp has depth there and the reference none (comparable with the strict count)
    assert np.array_equal(m.edge_mask, np.isfinite(plain) & ~np.isfinite(m.depth))
    assert mask.sum() < m.edge_mask.sum() < 3 * mask.sum()
    # where both have depth, the mixed reference is the strict warp without the distrusted samples
    both = np.isfinite(m.depth) & np.isfinite(refs["strict"].depth)
    assert np.mean(m.depth[both] == refs["strict"].depth[both]) > 0.98
