"""DDD's pieces against direct formulas: BerHu (eq. 26), splatting (eq. 21), partial convolution,
surface prior (eq. 27), photometric loss (eq. 23-25)."""
from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from methods.ddd.losses import (berhu, berhu_threshold, charbonnier, depth_prior_loss, photometric_loss,
                                surface_prior_loss, tukey)
from methods.ddd.partial_conv import PartialConv2d, partial_conv2d
from methods.ddd.splatting import depth_weight, project_to, render_view, splat

D = torch.float64


# ------------------------------------------------------------------------------------------ BerHu
def test_berhu_branches_and_threshold_over_valid_pixels():
    r = torch.tensor([[[[0.01, -0.02, 0.05], [0.3, -0.5, 2.0]]]], dtype=D)
    valid = torch.tensor([[[[True, True, True], [True, True, False]]]])
    c = berhu_threshold(r, valid)
    assert float(c) == pytest.approx(0.2 * 0.5)  # the invalid 2.0 does not count
    assert float(berhu_threshold(r, valid, over="all")) == pytest.approx(0.2 * 2.0)  # the released code's choice
    b = berhu(r, c)
    for x, y in zip(r.flatten().tolist(), b.flatten().tolist()):
        expect = abs(x) if abs(x) <= 0.1 else (x * x + 0.01) / 0.2
        assert y == pytest.approx(expect)
    # continuous at |r| = c, quadratic branch above
    assert float(berhu(torch.tensor(0.1, dtype=D), 0.1)) == pytest.approx(float(berhu(torch.tensor(0.1 + 1e-12, dtype=D), 0.1)))
    pred = torch.zeros_like(r)
    expect = np.mean([abs(x) if abs(x) <= 0.1 else (x * x + 0.01) / 0.2 for x, ok in zip(r.flatten().tolist(), valid.flatten().tolist()) if ok])
    assert float(depth_prior_loss(pred, r, valid)) == pytest.approx(expect)


# ------------------------------------------------------------------------------------- splatting
K8 = torch.tensor([[20.0, 20.0, 3.5, 3.5]], dtype=D)


def test_projection_with_the_identity_returns_the_pixel_grid():
    d = torch.rand(1, 1, 8, 8, dtype=D) + 1
    uv, z = project_to(d, K8, torch.eye(4, dtype=D)[None], K8)
    v, u = torch.meshgrid(torch.arange(8, dtype=D), torch.arange(8, dtype=D), indexing="ij")
    torch.testing.assert_close(uv[0, 0], u)
    torch.testing.assert_close(uv[0, 1], v)
    torch.testing.assert_close(z, d)


def test_splat_conserves_weight_and_puts_a_point_at_its_subpixel_position():
    values = torch.rand(1, 2, 5, 5, dtype=D)
    w = torch.rand(1, 1, 5, 5, dtype=D)
    uv = torch.rand(1, 2, 5, 5, dtype=D) * 6 + 0.5  # all four neighbours inside an 8x8 target
    acc, wacc = splat(values, uv, w, (8, 8))
    assert float(wacc.sum()) == pytest.approx(float(w.sum()), rel=1e-12)
    for c in range(2):
        assert float(acc[0, c].sum()) == pytest.approx(float((values[0, c] * w[0, 0]).sum()), rel=1e-12)
    # a single point at (u, v) = (2.3, 4.6): bilinear weights, centroid at the projection
    one = torch.zeros(1, 1, 1, 1, dtype=D) + 1
    acc, wacc = splat(one, torch.tensor([2.3, 4.6], dtype=D).view(1, 2, 1, 1), one, (8, 8))
    W = wacc[0, 0]
    assert float(W[4, 2]) == pytest.approx(0.7 * 0.4) and float(W[4, 3]) == pytest.approx(0.3 * 0.4)
    assert float(W[5, 2]) == pytest.approx(0.7 * 0.6) and float(W[5, 3]) == pytest.approx(0.3 * 0.6)
    v, u = torch.meshgrid(torch.arange(8, dtype=D), torch.arange(8, dtype=D), indexing="ij")
    assert float((W * u).sum()) == pytest.approx(2.3) and float((W * v).sum()) == pytest.approx(4.6)


def test_splat_drops_what_falls_outside_and_passes_gradients_to_positions():
    one = torch.ones(1, 1, 1, 1, dtype=D)
    _, wacc = splat(one, torch.tensor([-0.5, 2.0], dtype=D).view(1, 2, 1, 1), one, (4, 4))
    assert float(wacc.sum()) == pytest.approx(0.5)
    uv = torch.tensor([1.25, 1.0], dtype=D).view(1, 2, 1, 1).requires_grad_(True)
    _, wacc = splat(one, uv, one, (4, 4))
    wacc[0, 0, 1, 2].backward()  # weight at u = 2 grows as u moves right
    assert float(uv.grad[0, 0]) == pytest.approx(1.0)


def test_rendering_a_moved_view_puts_points_at_their_projection_and_nearer_points_win():
    # two source pixels seen by a camera; the target is the same camera: colours land on their pixels
    K = torch.tensor([[10.0, 10.0, 2.0, 2.0]], dtype=D)
    depth = torch.full((1, 1, 5, 5), 2.0, dtype=D)
    valid = torch.zeros(1, 1, 5, 5, dtype=torch.bool)
    valid[0, 0, 1, 1] = valid[0, 0, 3, 3] = True
    color = torch.zeros(1, 3, 5, 5, dtype=D)
    color[0, :, 1, 1] = torch.tensor([1.0, 0.0, 0.0], dtype=D)
    color[0, :, 3, 3] = torch.tensor([0.0, 1.0, 0.0], dtype=D)
    T = torch.eye(4, dtype=D)[None].clone()
    T[0, 0, 3] = 0.1  # move 0.1 m along x: 10 px/m * 0.1 m / 2 m = 0.5 px to the right
    img, z, w = render_view([dict(depth=depth, valid=valid, color=color, K=K, T_ts=T)], K, (5, 5), z_max=3.0)
    assert float(w[0, 0, 1, 1]) == pytest.approx(0.5 * float(depth_weight(torch.tensor(2.0), z_max=3.0)))
    torch.testing.assert_close(img[0, :, 1, 1], color[0, :, 1, 1])
    torch.testing.assert_close(img[0, :, 1, 2], color[0, :, 1, 1])
    torch.testing.assert_close(z[0, 0, 1, 1:3], torch.tensor([2.0, 2.0], dtype=D))
    # two sources land on one pixel: the nearer dominates by exp(-2 z / z_max)
    near = dict(depth=torch.full((1, 1, 1, 1), 1.0, dtype=D), valid=torch.ones(1, 1, 1, 1, dtype=torch.bool),
                color=torch.tensor([1.0, 0.0, 0.0], dtype=D).view(1, 3, 1, 1), K=torch.tensor([[10.0, 10.0, 0.0, 0.0]], dtype=D),
                T_ts=torch.eye(4, dtype=D)[None])
    far = dict(near, depth=torch.full((1, 1, 1, 1), 3.0, dtype=D), color=torch.tensor([0.0, 1.0, 0.0], dtype=D).view(1, 3, 1, 1))
    img, _, _ = render_view([near, far], torch.tensor([[10.0, 10.0, 0.0, 0.0]], dtype=D), (2, 2), z_max=3.0)
    w1, w3 = np.exp(-2 / 3), np.exp(-2)
    assert float(img[0, 0, 0, 0]) == pytest.approx(w1 / (w1 + w3)) and float(img[0, 0, 0, 0]) > 0.75


# ------------------------------------------------------------------------------ partial convolution
def test_partial_conv_ignores_holes_and_rescales_partial_windows():
    torch.manual_seed(0)
    conv = PartialConv2d(2, 3, 3).double()
    x = torch.randn(1, 2, 6, 7, dtype=D)
    mask = (torch.rand(1, 1, 6, 7) > 0.4).double()
    mask[0, 0, :, 5:] = 0  # a hole band two pixels wide
    with torch.no_grad():
        y, m = conv(x, mask)
    x2 = x.clone()
    x2[mask.expand_as(x) == 0] = 1e6  # anything under the holes
    with torch.no_grad():
        y2, _ = conv(x2, mask)
    torch.testing.assert_close(y, y2)
    W, b = conv.weight.detach(), conv.bias.detach()
    xp, mp = F.pad(x, (1, 1, 1, 1)), F.pad(mask, (1, 1, 1, 1))
    for i in range(6):
        for j in range(7):
            win_m = mp[0, 0, i:i + 3, j:j + 3]
            n = float(win_m.sum())
            assert float(m[0, 0, i, j]) == (1.0 if n > 0 else 0.0)  # mask propagation: any valid pixel in the window
            for o in range(3):
                expect = 0.0 if n == 0 else float((W[o] * xp[0, :, i:i + 3, j:j + 3] * win_m).sum()) * 9 / n + float(b[o])
                assert float(y[0, o, i, j]) == pytest.approx(expect, abs=1e-10)
    assert float(m[0, 0, :, 6].sum()) == 0  # two pixels into a hole band: still a hole after one 3x3


def test_partial_conv_with_a_full_mask_is_an_ordinary_convolution():
    conv = PartialConv2d(1, 2, 5, stride=2).double()
    x = torch.randn(1, 1, 9, 9, dtype=D)
    y, m = partial_conv2d(x, torch.ones(1, 1, 9, 9, dtype=D), conv.weight, conv.bias, stride=2, padding=2)
    ref = F.conv2d(x, conv.weight, conv.bias, stride=2, padding=2)
    inner = (slice(None), slice(None), slice(1, -1), slice(1, -1))  # border windows are partial (zero padding)
    torch.testing.assert_close(y[inner], ref[inner])
    assert bool((m == 1).all())


# --------------------------------------------------------------------------------- surface prior
def test_surface_prior_is_zero_on_a_plane_and_matches_a_loop():
    n = torch.nn.functional.normalize(torch.tensor([0.2, -0.1, -1.0], dtype=D), dim=0).view(1, 3, 1, 1).expand(1, 3, 5, 6)
    valid = torch.ones(1, 1, 5, 6, dtype=torch.bool)
    assert float(surface_prior_loss(n, valid)) == pytest.approx(0.0, abs=1e-12)
    rng = np.random.default_rng(7)
    N = rng.normal(size=(3, 5, 6))
    N /= np.linalg.norm(N, axis=0)
    V = rng.random((5, 6)) > 0.3
    per = []
    for i in range(5):
        for j in range(6):
            if not V[i, j]:
                continue
            cos = [abs(N[:, i, j] @ N[:, a, b]) for a in range(i - 1, i + 2) for b in range(j - 1, j + 2)
                   if (a, b) != (i, j) and 0 <= a < 5 and 0 <= b < 6 and V[a, b]]
            if cos:
                per.append(np.mean(cos))
    got = surface_prior_loss(torch.from_numpy(N)[None], torch.from_numpy(V)[None, None])
    assert float(got) == pytest.approx(1 - np.mean(per), rel=1e-12)


# ---------------------------------------------------------------------------------- photometric
def test_penalties_and_photometric_loss():
    x = torch.tensor([0.0, 0.5, 2.0, 3.0], dtype=D)
    torch.testing.assert_close(charbonnier(x, gamma=0.1), torch.sqrt(x * x + 0.01) - 0.1)
    c = 2.2
    expect = [c * c / 6 * (1 - (1 - (v / c) ** 2) ** 3) if v <= c else c * c / 6 for v in x.tolist()]
    np.testing.assert_allclose(tukey(x).numpy(), expect)
    img = torch.rand(1, 3, 16, 16, dtype=D)
    mask = torch.ones(1, 1, 16, 16, dtype=torch.bool)
    loss, parts = photometric_loss(img, img, mask)
    assert float(loss) == pytest.approx(0.0, abs=1e-12)
    other = torch.rand(1, 3, 16, 16, dtype=D)
    loss, parts = photometric_loss(other, img, mask)
    col = (other - img).abs().sum(1)
    assert float(parts["col"]) == pytest.approx(float((torch.sqrt(col ** 2 + 1e-6) - 1e-3).mean()))
    assert float(loss) == pytest.approx(0.15 * float(parts["col"]) + 0.85 * float(parts["str"]))
    assert float(parts["str"]) > 0.1
