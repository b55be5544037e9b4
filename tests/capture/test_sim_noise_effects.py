"""The noise effects added from the diagnosis of real captures (issue 13), each against its
formula, and the measured sensor profiles."""
from __future__ import annotations

import numpy as np
import pytest

from capture.sim.noise import StereoNoise, TofNoise, profile_names, sensor_profile, stereo_depth, tof_depth

H, W, FX, CX = 200, 240, 300.0, 119.5


def _stereo(noise: StereoNoise, z0: float = 1.5, seed: int = 0):
    z = np.full((H, W), z0, np.float32)
    ray_x = ((np.arange(W) - CX) / FX)[None, :].repeat(H, 0).astype(np.float32)
    lum = np.random.default_rng(seed).uniform(0.3, 0.7, (H, W)).astype(np.float32)
    return stereo_depth(z, ray_x, lum, noise=noise, fx=FX, cx=CX, rng=np.random.default_rng(seed)).depth


def test_effects_off_by_default_leave_the_default_sensor_unchanged():
    a = _stereo(StereoNoise())
    b = _stereo(StereoNoise(noise_floor_m=0.0, outlier_fraction=0.0, depth_offset_m=0.0, disparity_offset_px=0.0))
    assert np.array_equal(a, b, equal_nan=True)


def test_depth_and_disparity_offsets():
    base = np.nanmean(_stereo(StereoNoise()) - 1.5)
    assert np.nanmean(_stereo(StereoNoise(depth_offset_m=-0.05)) - 1.5) - base == pytest.approx(-0.05, abs=5e-4)
    delta, fB = -1.0, FX * 0.055
    expected = 1.5 / (1 + delta * 1.5 / fB) - 1.5  # z = fB / (d + delta)
    got = np.nanmedian(_stereo(StereoNoise(disparity_offset_px=delta))) - 1.5
    assert got == pytest.approx(expected, rel=0.05)


def test_noise_floor_adds_in_quadrature_and_outliers_have_their_fraction():
    n0 = StereoNoise(correlation_px=0.0)
    s0 = np.nanstd(_stereo(n0, z0=0.8))
    s1 = np.nanstd(_stereo(StereoNoise(correlation_px=0.0, noise_floor_m=0.004), z0=0.8))
    assert s1 == pytest.approx(np.hypot(s0, 0.004), rel=0.05)
    d = _stereo(StereoNoise(outlier_fraction=0.02))
    far = np.abs(d - 1.5) > 0.1
    assert far[np.isfinite(d)].mean() == pytest.approx(0.02 * (1 - 0.2 / 9.7), abs=0.004)


def test_tof_correlation_follows_the_gaussian_model():
    z = np.full((H, W), 2.0, np.float32)
    d = tof_depth(z, np.full((H, W), 0.8, np.float32), noise=TofNoise(correlation_px=1.5),
                  rng=np.random.default_rng(1)).depth - 2.0
    rho1 = np.corrcoef(d[:, :-1].ravel(), d[:, 1:].ravel())[0, 1]
    assert rho1 == pytest.approx(np.exp(-1 / (4 * 1.5 ** 2)), abs=0.03)
    assert np.std(d) == pytest.approx(TofNoise().sigma_z(2.0), rel=0.05)


def test_measured_profiles():
    names = profile_names()
    for name in ("D415", "D435", "Azure Kinect", "Kinect v1"):
        assert name in names
    assert isinstance(sensor_profile("Azure Kinect"), TofNoise)
    d435 = sensor_profile("D435")
    assert isinstance(d435, StereoNoise) and d435.baseline_m == 0.05 and d435.subpixel_px > 0.08
    with pytest.raises(Exception, match="unknown"):
        sensor_profile("D999")
