"""Bilateral filter on depth against a direct loop implementation of eq. 5-8, holes included."""
import math

import numpy as np
import pytest

from methods import MethodError, get
from functools import partial

from methods import bilateral

# the tests pin every parameter (the swept default of depth_adaptive is True); a call may still set it
bilateral_filter = partial(bilateral.bilateral_filter, depth_adaptive=False)
from methods.tools.synthetic import synthetic_scene


def bilateral_loop(f, sigma_d, sigma_r, radius, *, fill=False, adaptive=False, z_ref=2.0):
    """Eq. 5-8 literally, in float64: h(x) = sum f(xi) c(xi, x) s(f(xi), f(x)) / k(x), holes left out."""
    H, W = f.shape
    out = np.full((H, W), np.nan)
    for y in range(H):
        for x in range(W):
            fx = float(f[y, x])
            if math.isnan(fx) and not fill:
                continue
            sr = sigma_r * (fx / z_ref) ** 2 if adaptive else sigma_r
            num = den = 0.0
            for j in range(-radius, radius + 1):
                for i in range(-radius, radius + 1):
                    if i * i + j * j > radius * radius:
                        continue
                    yy, xx = y + j, x + i
                    if not (0 <= yy < H and 0 <= xx < W) or math.isnan(f[yy, xx]):
                        continue
                    fxi = float(f[yy, xx])
                    c = math.exp(-0.5 * (math.hypot(i, j) / sigma_d) ** 2)               # eq. 7
                    s = 1.0 if math.isnan(fx) else math.exp(-0.5 * ((fxi - fx) / sr) ** 2)  # eq. 8
                    num += fxi * c * s                                                     # eq. 5
                    den += c * s                                                           # eq. 6
            if den > 0:
                out[y, x] = num / den
    return out


@pytest.fixture(scope="module")
def small():
    """14x17 depth: two surfaces 0.8 m apart, noise, holes (one touching the edge)."""
    rng = np.random.default_rng(3)
    d = np.where(np.arange(17)[None, :] < 8, 1.2, 2.0) + 0.01 * rng.standard_normal((14, 17))
    d[3:6, 6:8] = np.nan      # hole touching the step
    d[0, 0] = np.nan          # hole in a corner
    d[10, 12] = np.nan
    return d.astype(np.float32)


@pytest.mark.parametrize("sigma_d, sigma_r, radius", [(1.5, 0.02, 3), (2.0, 0.5, 4), (1.0, 0.005, 1)])
def test_matches_loop_reference(small, sigma_d, sigma_r, radius):
    ours = bilateral_filter(small, sigma_spatial=sigma_d, sigma_color=sigma_r, radius=radius)
    ref = bilateral_loop(small, sigma_d, sigma_r, radius)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=2e-6)     # NaN positions must match too
    assert ours.dtype == np.float32


def test_depth_adaptive_matches_loop_reference(small):
    ours = bilateral_filter(small, sigma_spatial=1.5, sigma_color=0.02, radius=3, depth_adaptive=True, z_ref=1.5)
    ref = bilateral_loop(small, 1.5, 0.02, 3, adaptive=True, z_ref=1.5)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=2e-6)


def test_fill_holes_matches_loop_reference(small):
    ours = bilateral_filter(small, sigma_spatial=1.5, sigma_color=0.02, radius=3, fill_holes=True)
    ref = bilateral_loop(small, 1.5, 0.02, 3, fill=True)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=2e-6)
    assert np.isfinite(ours).all()


def test_hole_next_to_edge_is_not_pulled_to_zero_and_no_hole_is_invented():
    d = np.full((20, 20), 1.5, np.float32)
    d[:, 10:] = 2.5
    d[8:12, 7:10] = np.nan              # hole right against the step, on the near side
    out = bilateral_filter(d, sigma_spatial=2.0, sigma_color=0.05, radius=4)
    assert np.array_equal(np.isnan(out), np.isnan(d))          # holes stay holes, none invented
    near = out[:, :10][np.isfinite(d[:, :10])]
    far = out[:, 10:]
    np.testing.assert_allclose(near, 1.5, atol=1e-6)           # not pulled toward 0, nor across the edge
    np.testing.assert_allclose(far, 2.5, atol=1e-6)
    # a filter that reads holes as 0 would drag the neighbours down: make sure we would notice
    naive = np.nan_to_num(d)
    import cv2
    assert cv2.bilateralFilter(naive, 9, 2.0, 2.0)[10, 6] < 1.45


def test_noise_goes_down_and_edges_stay():
    truth, noisy = synthetic_scene((96, 128), seed=2)
    out = bilateral_filter(noisy, sigma_spatial=2.0, sigma_color=0.03)
    m = np.isfinite(out)
    assert np.array_equal(m, np.isfinite(noisy))
    err_raw = np.sqrt(np.mean((noisy - truth)[m] ** 2))
    err_out = np.sqrt(np.mean((out - truth)[m] ** 2))
    assert err_out < 0.8 * err_raw


def test_sigma_color_inf_is_the_gaussian():
    from methods.gaussian import gaussian_filter
    _, noisy = synthetic_scene((40, 50), seed=4)
    a = bilateral_filter(noisy, sigma_spatial=1.5, sigma_color=math.inf, radius=3)
    b = gaussian_filter(noisy, sigma_spatial=1.5, radius=3)
    np.testing.assert_allclose(a, b, atol=2e-6)


@pytest.mark.parametrize("kwargs, fragment", [
    (dict(sigma_color=-0.01), "sigma_color must be a positive number of metres"),
    (dict(sigma_spatial=0.0), "sigma_spatial must be a positive number of pixels"),
    (dict(sigma_spatial=-1.0), "sigma_spatial"),
    (dict(radius=0), "radius must be an integer"),
    (dict(radius=2.5), "radius must be an integer"),
    (dict(radius=math.inf), "radius must be an integer"),
    (dict(sigma_spatial=math.nan), "sigma_spatial"),
    (dict(sigma_color="wide"), "sigma_color must be a number"),
    (dict(fill_holes="yes"), "fill_holes must be true or false"),
    (dict(z_ref=-2.0), "z_ref"),
])
def test_bad_parameters(kwargs, fragment):
    d = np.ones((8, 8), np.float32)
    with pytest.raises(MethodError, match=fragment):
        bilateral_filter(d, **kwargs)
    with pytest.raises(MethodError, match=fragment):
        get("bilateral", **kwargs)


@pytest.mark.parametrize("depth, fragment", [
    (np.ones((8, 8), np.float64), "float32"),
    (np.ones((8, 8), np.uint16), "float32"),
    (np.full((8, 8), np.nan, np.float32), "all NaN"),
    (np.zeros((8, 8, 3), np.float32), "shape"),
    (np.where(np.eye(8) > 0, 0.0, 1.0).astype(np.float32), "NaN, not 0"),
    (np.where(np.eye(8) > 0, np.inf, 1.0).astype(np.float32), "infinite"),
])
def test_bad_depth(depth, fragment):
    with pytest.raises(MethodError, match=fragment):
        bilateral_filter(depth)
    with pytest.raises(MethodError, match=fragment):
        get("bilateral").denoise(depth)


def test_denoiser_class_delegates(small):
    m = get("bilateral", sigma_spatial=1.5, sigma_color=0.02, radius=3, depth_adaptive=False)
    np.testing.assert_array_equal(m.denoise(small), bilateral_filter(small, sigma_spatial=1.5, sigma_color=0.02,
                                                                      radius=3))
    assert m.key != get("bilateral", sigma_spatial=1.5, sigma_color=0.03, radius=3, depth_adaptive=False).key
    assert "sigma_color=0.02" in m.key
