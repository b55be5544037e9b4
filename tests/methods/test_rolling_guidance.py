"""Rolling Guidance Filter (Zhang et al., eq. 9-11): loop reference, Fig. 2/3 behaviour, OpenCV's deviation."""
import math

import cv2
import numpy as np
import pytest

from methods import MethodError, get
from methods._kernels import joint_mean
from functools import partial

from methods import rolling_guidance

# the tests pin every parameter (the swept default of depth_adaptive is True); a call may still set it
rolling_guidance_filter = partial(rolling_guidance.rolling_guidance_filter, depth_adaptive=False)


def _gaussian_pass(I, sigma_s, radius):
    """Eq. 10 over the valid pixels of I; defined at holes too (J^1 is needed there as a guide)."""
    H, W = I.shape
    J = np.full((H, W), np.nan)
    for y in range(H):
        for x in range(W):
            num = den = 0.0
            for j in range(-radius, radius + 1):
                for i in range(-radius, radius + 1):
                    yy, xx = y + j, x + i
                    if i * i + j * j <= radius * radius and 0 <= yy < H and 0 <= xx < W and not math.isnan(I[yy, xx]):
                        w = math.exp(-(i * i + j * j) / (2 * sigma_s ** 2))
                        num += w * float(I[yy, xx])
                        den += w
            if den > 0:
                J[y, x] = num / den
    return J


def _joint_pass(I, J, sigma_s, sigma_r, radius, *, adaptive=False, z_ref=2.0):
    """Eq. 11: J^{t+1}(p) = sum_q exp(-|p-q|^2/2sigma_s^2 - (J(p)-J(q))^2/2sigma_r^2) I(q) / K_p, q valid in I."""
    H, W = I.shape
    out = np.full((H, W), np.nan)
    for y in range(H):
        for x in range(W):
            if math.isnan(J[y, x]):
                continue
            sr = sigma_r * (J[y, x] / z_ref) ** 2 if adaptive else sigma_r
            num = den = 0.0
            for j in range(-radius, radius + 1):
                for i in range(-radius, radius + 1):
                    yy, xx = y + j, x + i
                    if i * i + j * j <= radius * radius and 0 <= yy < H and 0 <= xx < W and not math.isnan(I[yy, xx]):
                        w = math.exp(-(i * i + j * j) / (2 * sigma_s ** 2) - (J[y, x] - J[yy, xx]) ** 2 / (2 * sr ** 2))
                        num += w * float(I[yy, xx])
                        den += w
            if den > 0:
                out[y, x] = num / den
    return out


def rgf_loop(I, sigma_s, sigma_r, iterations, radius, *, fill=False, adaptive=False, z_ref=2.0):
    J = _gaussian_pass(I, sigma_s, radius)                       # J^1 = G (eq. 10)
    for _ in range(iterations - 1):
        J = _joint_pass(I, J, sigma_s, sigma_r, radius, adaptive=adaptive, z_ref=z_ref)
    if not fill:
        J[np.isnan(I)] = np.nan
    return J


@pytest.fixture(scope="module")
def small():
    rng = np.random.default_rng(11)
    d = np.where(np.arange(15)[None, :] < 7, 1.3, 2.2) + 0.02 * rng.standard_normal((12, 15))
    d[(np.arange(12) % 4 == 1)[:, None] & (np.arange(15) % 4 == 1)[None, :]] += 0.15   # 1-px structures
    d[4:7, 5:7] = np.nan
    d[0, 14] = np.nan
    return d.astype(np.float32)


@pytest.mark.parametrize("kw", [dict(), dict(fill=True), dict(adaptive=True, z_ref=1.7)])
def test_matches_loop_reference(small, kw):
    ours = rolling_guidance_filter(small, sigma_spatial=1.5, sigma_color=0.05, iterations=3, radius=3,
                                   fill_holes=kw.get("fill", False), depth_adaptive=kw.get("adaptive", False),
                                   z_ref=kw.get("z_ref"))
    ref = rgf_loop(small, 1.5, 0.05, 3, 3, **kw)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=3e-6)
    assert ours.dtype == np.float32


def test_one_iteration_is_the_gaussian(small):
    ours = rolling_guidance_filter(small, sigma_spatial=1.5, sigma_color=0.05, iterations=1, radius=3)
    np.testing.assert_allclose(ours, rgf_loop(small, 1.5, 0.05, 1, 3), atol=2e-6)


# ----------------------------------------------------------------------------- Fig. 2 / Fig. 3 behaviour
def fig2_signal(n=200):
    """1-D: a plateau with 2-px bumps (0.1 m, smaller than sigma_s) next to a large 0.5 m step."""
    x = np.arange(n)
    s = np.where(x < n // 2, 1.0, 1.5) + 0.1 * (((x % 20) < 2) & (x > 8) & (x < n // 2 - 10))
    return s


SS, SR, IT, R = 3.0, 0.02, 4, 6


def _bumps(row, n=200):
    seg = row[10:n // 2 - 12]
    return float(seg.max() - seg.min())


def test_fig2_1d_small_structures_removed_large_edge_kept():
    s = fig2_signal()
    out = rolling_guidance_filter(s[None, :].astype(np.float32), sigma_spatial=SS, sigma_color=SR, iterations=IT,
                                  radius=R)[0]
    np.testing.assert_allclose(out, rgf_loop(s[None, :].astype(np.float32), SS, SR, IT, R)[0], atol=3e-6)
    assert _bumps(out) < 0.35 * 0.1                               # bumps mostly gone
    assert abs(out[97] - 1.0) < 0.01 and abs(out[102] - 1.5) < 0.01   # the step stays a step
    assert abs(out[99] - 1.0) < 0.05 and abs(out[100] - 1.5) < 0.05


def test_fig3_2d_small_squares_removed_large_disk_kept():
    from scipy.ndimage import distance_transform_edt
    H = W = 72
    yy, xx = np.mgrid[:H, :W]
    img = np.full((H, W), 2.0)
    small = ((yy % 10) < 2) & ((xx % 10) < 2) & (yy > 3) & (xx > 3) & (yy < H - 4) & (xx < W - 4)
    disk = (yy - 36) ** 2 + (xx - 36) ** 2 <= 18 ** 2
    img[small] -= 0.1
    img[disk] = 1.4
    img = img.astype(np.float32)
    ours = rolling_guidance_filter(img, sigma_spatial=SS, sigma_color=SR, iterations=IT, radius=R)
    cvo = cv2.ximgproc.rollingGuidanceFilter(img, d=2 * R + 1, sigmaColor=SR, sigmaSpace=SS, numOfIter=IT)
    away = ~disk & (distance_transform_edt(~disk) > 4)
    inside = distance_transform_edt(disk) >= 2
    assert np.abs(ours - 2.0)[away].max() < 0.015          # 0.1 m squares of 2x2 px: gone
    assert np.abs(ours - 1.4)[inside].max() < 1e-3         # the large disk: kept, sharp
    assert np.abs(cvo - 2.0)[away].max() > 0.09            # OpenCV keeps the squares


def test_opencv_variant_measurably_differs_and_why():
    """OpenCV's rollingGuidanceFilter starts from J = I (a bilateral first pass), not the Gaussian (eq. 10).

    Rows are tiled so the middle row sees no top/bottom border (OpenCV reflects, we leave the outside out).
    """
    s = fig2_signal()
    img = np.tile(s, (2 * IT * R + 9, 1)).astype(np.float32)
    mid = img.shape[0] // 2
    paper = rolling_guidance_filter(img, sigma_spatial=SS, sigma_color=SR, iterations=IT, radius=R)[mid]
    cvo = cv2.ximgproc.rollingGuidanceFilter(img, d=2 * R + 1, sigmaColor=SR, sigmaSpace=SS, numOfIter=IT)[mid]
    # OpenCV's scheme with our kernel: J^0 = I, then `iterations` joint passes
    J = img.copy()
    for _ in range(IT):
        J = joint_mean(img, J, 0.5 / SR ** 2, sigma_spatial=SS, radius=R, ref=J)
    opencv_scheme = J[mid]
    interior = slice(IT * R, img.shape[1] - IT * R)
    assert np.abs(cvo - opencv_scheme)[interior].max() < 2e-3     # OpenCV == "start from I" (up to its exp table)
    assert np.abs(cvo - paper)[interior].max() > 0.05              # ... which is not the paper's filter
    assert _bumps(cvo) > 0.9 * 0.1 and _bumps(paper) < 0.4 * 0.1


def test_holes_stay_holes_and_are_not_pulled_to_zero():
    d = np.full((24, 24), 1.5, np.float32)
    d[:, 12:] = 2.5
    d[9:14, 9:12] = np.nan
    out = rolling_guidance_filter(d, sigma_spatial=2.0, sigma_color=0.05, iterations=4, radius=4)
    assert np.array_equal(np.isnan(out), np.isnan(d))
    np.testing.assert_allclose(out[:, :12][np.isfinite(d[:, :12])], 1.5, atol=1e-3)
    filled = rolling_guidance_filter(d, sigma_spatial=2.0, sigma_color=0.05, iterations=4, radius=4, fill_holes=True)
    assert np.isfinite(filled).all() and filled[9:14, 9:12].min() > 1.4


@pytest.mark.parametrize("kwargs, fragment", [
    (dict(sigma_color=-1.0), "sigma_color must be a positive number of metres"),
    (dict(sigma_spatial=-3.0), "sigma_spatial must be a positive"),
    (dict(iterations=0), "iterations must be an integer"),
    (dict(iterations=2.5), "iterations must be an integer"),
    (dict(iterations=float("nan")), "iterations must be an integer"),
])
def test_bad_parameters(kwargs, fragment):
    with pytest.raises(MethodError, match=fragment):
        rolling_guidance_filter(np.ones((6, 6), np.float32), **kwargs)
    with pytest.raises(MethodError, match=fragment):
        get("rolling_guidance", **kwargs)
