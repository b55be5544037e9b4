"""Joint bilateral filter (range kernel on the colour image) against a direct loop, holes included."""
import math

import numpy as np
import pytest

from methods import MethodError, get
from methods.joint_bilateral import joint_bilateral_filter


def joint_bilateral_loop(f, C, sigma_d, sigma_r, radius, *, fill=False):
    """Eq. 5-8 with s() on the colour guide C (Euclidean over channels), holes of f left out."""
    H, W = f.shape
    C = C.astype(np.float64).reshape(H, W, -1)
    out = np.full((H, W), np.nan)
    for y in range(H):
        for x in range(W):
            if math.isnan(f[y, x]) and not fill:
                continue
            num = den = 0.0
            for j in range(-radius, radius + 1):
                for i in range(-radius, radius + 1):
                    if i * i + j * j > radius * radius:
                        continue
                    yy, xx = y + j, x + i
                    if not (0 <= yy < H and 0 <= xx < W) or math.isnan(f[yy, xx]):
                        continue
                    delta = np.linalg.norm(C[yy, xx] - C[y, x])
                    w = math.exp(-0.5 * (math.hypot(i, j) / sigma_d) ** 2) * math.exp(-0.5 * (delta / sigma_r) ** 2)
                    num += w * float(f[yy, xx])
                    den += w
            if den > 0:
                out[y, x] = num / den
    return out


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(5)
    H, W = 13, 16
    color = np.zeros((H, W, 3), np.uint8)
    color[:, :7] = (200, 40, 40)
    color[:, 7:] = (30, 30, 180)
    color = np.clip(color + rng.integers(-6, 7, (H, W, 3)), 0, 255).astype(np.uint8)
    depth = np.where(np.arange(W)[None, :] < 7, 1.4, 2.6) + 0.01 * rng.standard_normal((H, W))
    depth[4:7, 5:7] = np.nan
    depth[12, 0] = np.nan
    return depth.astype(np.float32), color


@pytest.mark.parametrize("sigma_d, sigma_r, radius", [(1.5, 10.0, 3), (2.0, 40.0, 4)])
def test_matches_loop_reference(scene, sigma_d, sigma_r, radius):
    depth, color = scene
    ours = joint_bilateral_filter(depth, color, sigma_spatial=sigma_d, sigma_color=sigma_r, radius=radius)
    ref = joint_bilateral_loop(depth, color, sigma_d, sigma_r, radius)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=2e-6)
    assert ours.dtype == np.float32


def test_fill_holes_and_grey_guide_match_loop_reference(scene):
    depth, color = scene
    ours = joint_bilateral_filter(depth, color, sigma_spatial=1.5, sigma_color=10.0, radius=3, fill_holes=True)
    np.testing.assert_allclose(ours, joint_bilateral_loop(depth, color, 1.5, 10.0, 3, fill=True), atol=2e-6)
    assert np.isfinite(ours).all()
    grey = color[..., 0].astype(np.float32)
    ours = joint_bilateral_filter(depth, grey, sigma_spatial=1.5, sigma_color=10.0, radius=3)
    np.testing.assert_allclose(ours, joint_bilateral_loop(depth, grey, 1.5, 10.0, 3), atol=2e-6)


def test_colour_edge_keeps_the_depth_edge(scene):
    depth, color = scene
    out = joint_bilateral_filter(depth, color, sigma_spatial=2.0, sigma_color=15.0, radius=4)
    assert np.nanmax(out[:, :7]) < 1.45 and np.nanmin(out[:, 7:]) > 2.55
    assert np.array_equal(np.isnan(out), np.isnan(depth))


@pytest.mark.parametrize("color, fragment", [
    (np.zeros((12, 16, 3), np.uint8), "color must have shape"),
    (np.zeros((13, 16, 4), np.uint8), "color must have shape"),
    (np.zeros((13, 16, 3), np.int64), "uint8, uint16 or float32"),
    (np.full((13, 16, 3), np.nan, np.float32), "NaN"),
])
def test_bad_colour(scene, color, fragment):
    depth, _ = scene
    with pytest.raises(MethodError, match=fragment):
        joint_bilateral_filter(depth, color)
    with pytest.raises(MethodError, match=fragment):
        get("joint_bilateral").denoise(depth, color)


def test_needs_colour_and_positive_sigmas(scene):
    depth, color = scene
    with pytest.raises(MethodError, match="needs the colour image"):
        get("joint_bilateral").denoise(depth)
    with pytest.raises(MethodError, match="sigma_color must be a positive number of colour levels"):
        joint_bilateral_filter(depth, color, sigma_color=-5)
    assert get("joint_bilateral").uses_color
