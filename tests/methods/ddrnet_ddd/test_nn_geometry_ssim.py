"""Shared torch pieces: back-projection, four-neighbour normals, SSIM against scikit-image."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from capture.camera import Intrinsics
from methods.nn.geometry import backproject, normals_from_depth
from methods.nn.ssim import ssim, ssim_map

K = torch.tensor([50.0, 55.0, 15.5, 11.5], dtype=torch.float64)


def test_backproject_matches_intrinsics():
    intr = Intrinsics(32, 24, 50.0, 55.0, 15.5, 11.5)
    rng = np.random.default_rng(0)
    d = rng.uniform(0.5, 3.0, (24, 32))
    p = backproject(torch.from_numpy(d)[None, None], K)[0].permute(1, 2, 0).numpy()
    np.testing.assert_allclose(p, intr.depth_to_points(d.astype(np.float32)), rtol=1e-6)


def _plane_depth(n, c, h=24, w=32):
    """Depth of the plane ``n . X = c`` seen through K (ray r: z = c / (n . r))."""
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    r = np.stack([(u - 15.5) / 50.0, (v - 11.5) / 55.0, np.ones_like(u)])
    return c / np.tensordot(n, r, axes=1)


def test_normals_of_a_tilted_plane_are_its_normal_facing_the_camera():
    n_true = np.array([0.3, -0.2, -1.0])
    n_true /= np.linalg.norm(n_true)
    d = torch.from_numpy(_plane_depth(n_true, -2.0))[None, None]
    n, ok = normals_from_depth(d, K)
    assert not ok[0, 0, 0].any() and not ok[0, 0, :, -1].any()  # borders have no four neighbours
    assert ok[0, 0, 1:-1, 1:-1].all()
    got = n[0][:, ok[0, 0]].T.numpy()
    np.testing.assert_allclose(got, np.broadcast_to(n_true, got.shape), atol=1e-9)


def test_normals_next_to_a_hole_are_invalid():
    d = torch.full((1, 1, 8, 8), 2.0, dtype=torch.float64)
    d[0, 0, 4, 4] = float("nan")
    _, ok = normals_from_depth(d, K)
    for y, x in ((4, 4), (3, 4), (5, 4), (4, 3), (4, 5)):
        assert not ok[0, 0, y, x]
    assert ok[0, 0, 3, 3]


@pytest.mark.parametrize("channels", [1, 3])
def test_ssim_equals_scikit_image(channels):
    skm = pytest.importorskip("skimage.metrics")
    rng = np.random.default_rng(channels)
    a = rng.random((channels, 40, 37))
    b = np.clip(a + rng.normal(0, 0.2, a.shape), 0, 1)
    ours = ssim_map(torch.from_numpy(b)[None], torch.from_numpy(a)[None])[0].numpy()
    for c in range(channels):
        ref, full = skm.structural_similarity(a[c], b[c], gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                                              data_range=1.0, full=True)
        np.testing.assert_allclose(ours[c], full, atol=1e-10)
        if channels == 1:
            assert float(ssim(torch.from_numpy(b)[None], torch.from_numpy(a)[None])) == pytest.approx(ref, abs=1e-10)


def test_ssim_of_an_image_with_itself_is_one():
    x = torch.rand(1, 3, 20, 20, dtype=torch.float64)
    torch.testing.assert_close(ssim_map(x, x), torch.ones_like(x))
