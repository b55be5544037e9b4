"""DDRNet's loss terms (eq. 12-20) against direct formulas on tiny tensors."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from methods.ddrnet.losses import (DDRNetLoss, estimate_albedo, fidelity_loss, fit_lighting, normal_dot_loss,
                                   reconstruction_loss, render_shading, sh_basis, shading_loss, tv_loss)
from methods.nn.geometry import backproject, normals_from_depth

K = torch.tensor([40.0, 40.0, 9.5, 7.5], dtype=torch.float64)


def _t(a):
    return torch.as_tensor(np.asarray(a, dtype=np.float64))[None, None]


def test_reconstruction_and_fidelity_match_the_formulas():
    rng = np.random.default_rng(1)
    d, ref = rng.uniform(1, 2, (6, 7)), rng.uniform(1, 2, (6, 7))
    mask = rng.random((6, 7)) > 0.3
    r = (d - ref)[mask]
    m = torch.from_numpy(mask)[None, None]
    assert float(reconstruction_loss(_t(d), _t(ref), m)) == pytest.approx(np.abs(r).mean() + np.sqrt((r ** 2).mean()), rel=1e-9)
    assert float(fidelity_loss(_t(d), _t(ref), m)) == pytest.approx(np.sqrt((r ** 2).mean()), rel=1e-9)


def test_tv_of_a_ramp_is_the_sum_of_its_slopes():
    v, u = np.mgrid[0:9, 0:11].astype(np.float64)
    d = 1.0 + 0.03 * u - 0.02 * v
    full = torch.ones(1, 1, 9, 11, dtype=torch.bool)
    assert float(tv_loss(_t(d), full)) == pytest.approx(0.05, rel=1e-12)


def test_tv_with_holes_matches_a_direct_loop():
    rng = np.random.default_rng(2)
    d = rng.normal(size=(7, 8))
    mask = rng.random((7, 8)) > 0.25
    hx = [abs(d[i, j + 1] - d[i, j]) for i in range(7) for j in range(7) if mask[i, j] and mask[i, j + 1]]
    hy = [abs(d[i + 1, j] - d[i, j]) for i in range(6) for j in range(8) if mask[i, j] and mask[i + 1, j]]
    assert float(tv_loss(_t(d), torch.from_numpy(mask)[None, None])) == pytest.approx(np.mean(hx) + np.mean(hy), rel=1e-12)


def _plane(n, c, h=15, w=20):
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    r = np.stack([(u - 9.5) / 40.0, (v - 7.5) / 40.0, np.ones_like(u)])
    return c / np.tensordot(n, r, axes=1)


def test_normal_dot_is_zero_on_a_plane_and_matches_a_loop_elsewhere():
    n = np.array([0.2, 0.1, -1.0]) / np.linalg.norm([0.2, 0.1, -1.0])
    ref = _t(_plane(n, -1.5))
    n_ref, ok = normals_from_depth(ref, K)
    assert float(normal_dot_loss(ref, n_ref, K, ok)) == pytest.approx(0.0, abs=1e-24)
    # a plane at another distance but the same orientation: still zero (eq. 12 constrains orientation only)
    assert float(normal_dot_loss(_t(_plane(n, -2.0)), n_ref, K, ok)) == pytest.approx(0.0, abs=1e-24)
    rng = np.random.default_rng(3)
    d = _plane(n, -1.5) + rng.normal(0, 0.01, ref.shape[-2:])
    P = backproject(_t(d), K)[0].numpy()
    N, M = n_ref[0].numpy(), ok[0, 0].numpy()
    per = []
    for i in range(15):
        for j in range(20):
            if not M[i, j]:
                continue
            s = 0.0
            for di, dj in ((0, 1), (0, -1), (1, 0), (-1, 0)):
                a, b = i + di, j + dj
                if 0 <= a < 15 and 0 <= b < 20 and M[a, b]:
                    s += float(np.dot(P[:, i, j] - P[:, a, b], N[:, i, j])) ** 2
            per.append(s)
    assert float(normal_dot_loss(_t(d), n_ref, K, ok)) == pytest.approx(np.mean(per), rel=1e-9)


def _sphere(h=41, w=41):
    """Unit normals of a sphere filling the image (orthographic view), facing the camera (-z)."""
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    x, y = (u - (w - 1) / 2) / ((w - 1) / 2), (v - (h - 1) / 2) / ((h - 1) / 2)
    inside = x * x + y * y < 0.95
    z = -np.sqrt(np.clip(1 - x * x - y * y, 0, None))
    n = np.where(inside, np.stack([x, y, z]), 0.0)
    return torch.from_numpy(n)[None], torch.from_numpy(inside)[None, None]


def test_sh_basis_is_the_second_order_polynomial_set():
    n = torch.tensor([0.48, -0.6, -0.64], dtype=torch.float64).view(1, 3, 1, 1)
    x, y, z = 0.48, -0.6, -0.64
    np.testing.assert_allclose(sh_basis(n)[0, :, 0, 0].numpy(), [1, y, z, x, x * y, y * z, 3 * z * z - 1, z * x, x * x - y * y])


@pytest.mark.parametrize("textured", [False, True])
def test_lighting_solve_recovers_a_known_light_on_a_sphere(textured):
    n, inside = _sphere()
    light = torch.tensor([[0.6, 0.1, -0.25, 0.05, 0.02, -0.03, 0.04, 0.01, -0.02]], dtype=torch.float64)
    albedo = 1.0
    if textured:
        albedo = torch.from_numpy(np.random.default_rng(4).uniform(0.3, 1.0, (1, 1, 41, 41)))
    image = render_shading(light, n, albedo) * inside
    got = fit_lighting(n, image, inside, albedo=albedo, ridge=1e-10)
    np.testing.assert_allclose(got.numpy(), light.numpy(), atol=1e-7)


def test_shading_loss_is_zero_for_the_reference_normals_and_grows_away_from_them():
    n, inside = _sphere()
    light = torch.tensor([[0.6, 0.1, -0.25, 0.05, 0.02, -0.03, 0.04, 0.01, -0.02]], dtype=torch.float64)
    tex = torch.from_numpy(np.random.default_rng(5).uniform(0.4, 1.0, (1, 1, 41, 41)))
    image = render_shading(light, n, tex) * inside
    for albedo in ("ratio", "uniform"):
        img = image if albedo == "ratio" else render_shading(light, n) * inside
        assert float(shading_loss(n, n, img, inside, albedo=albedo, ridge=1e-10)) < 1e-5  # sqrt(eps) of the RMS terms
        tilted = torch.nn.functional.normalize(n + torch.tensor([0.3, 0.0, 0.0], dtype=torch.float64).view(1, 3, 1, 1), dim=1)
        assert float(shading_loss(tilted, n, img, inside, albedo=albedo)) > 1e-3
    # the ratio albedo is the texture up to the light/albedo scale ambiguity
    r = estimate_albedo(n, image, inside, kind="ratio", ridge=1e-10)
    q = (r[inside] / tex[inside]).numpy()
    assert q.std() / q.mean() < 0.05, (q.std(), q.mean())


def test_joint_loss_has_all_terms_and_released_terms_drops_two():
    rng = np.random.default_rng(6)
    ref = _t(_plane(np.array([0.0, 0.0, -1.0]), -1.5))
    d_dn = ref + _t(rng.normal(0, 0.01, ref.shape[-2:]))
    d_dt = ref + _t(rng.normal(0, 0.005, ref.shape[-2:]))
    grey = _t(rng.uniform(0.2, 0.8, ref.shape[-2:]))
    mask = torch.ones_like(ref, dtype=torch.bool)
    total, terms = DDRNetLoss()(d_dn=d_dn, d_dt=d_dt, ref=ref, mask=mask, K=K, grey=grey)
    assert set(terms) == {"rec", "dot", "sh", "fid", "smo"} and all(v > 0 for v in terms.values())
    _, rel = DDRNetLoss(released_terms=True)(d_dn=d_dn, d_dt=d_dt, ref=ref, mask=mask, K=K, grey=grey)
    assert rel["dot"] == 0 and rel["smo"] == 0 and rel["rec"] == terms["rec"]
    w = DDRNetLoss().w
    expect = w.rec * terms["rec"] + w.dot * terms["dot"] + w.lam * (w.sh * terms["sh"] + w.fid * terms["fid"] + w.smo * terms["smo"])
    assert float(total) == pytest.approx(expect, rel=1e-9)


def test_fill_holes_matches_a_direct_front_propagation_loop():
    from methods.ddrnet.model import fill_holes

    rng = np.random.default_rng(3)
    d = rng.uniform(1.0, 3.0, (9, 11)).astype(np.float32)
    d[2:7, 3:9] = np.nan          # a 5x6 hole: two steps fill it, the rest is the image mean
    d[0, 0] = np.nan
    out = fill_holes(torch.from_numpy(d)[None, None], steps=2)[0, 0].numpy()
    ref, known = np.nan_to_num(d), np.isfinite(d)
    for _ in range(2):
        nxt, grown = ref.copy(), known.copy()
        for i in range(9):
            for j in range(11):
                if known[i, j]:
                    continue
                win = [(y, x) for y in range(i - 1, i + 2) for x in range(j - 1, j + 2)
                       if 0 <= y < 9 and 0 <= x < 11 and known[y, x]]
                if win:
                    nxt[i, j], grown[i, j] = np.mean([ref[y, x] for y, x in win]), True
        ref, known = nxt, grown
    ref[~known] = ref[known].mean()
    np.testing.assert_allclose(out, ref, rtol=1e-5)
    full = torch.from_numpy(rng.uniform(1.0, 3.0, (1, 1, 5, 6)).astype(np.float32))
    assert torch.equal(fill_holes(full), full)
