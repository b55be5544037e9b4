"""Measured sensor profiles in the simulator (``--lq-profile`` / ``--hq-profile``, issue 13).

The reference is the profile file's own native numbers put through the physics by hand:
depth error ``sigma_z = z**2 hypot(subpixel, step / sqrt(12)) / (f_native B)`` and a Gaussian
correlation of ``correlation_px * f_image / f_native`` image pixels -- the same at every
``--scale``; nothing here goes through :func:`capture.sim.noise.in_pixels`.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from capture.camera import Intrinsics
from capture.sim.noise import PROFILES_PATH, StereoNoise, TofNoise, stereo_depth, tof_depth
from capture.sim.rigs import build_rig
from tests.capture.inproc_cli import run_inproc

PROFILES = json.loads(PROFILES_PATH.read_text())


def native(name: str) -> tuple[dict, float]:
    """The profile's stored parameters and native focal length (px), read straight from the file."""
    return PROFILES[name]["params"], float(PROFILES[name]["native_focal_px"])


def sigma_native(name: str, z_m: float) -> float:
    """Depth error (m) of the real sensor at ``z_m`` from the profile's native numbers."""
    p, f = native(name)
    return z_m ** 2 * float(np.hypot(p["subpixel_px"], p["disparity_step_px"] / np.sqrt(12))) / (f * p["baseline_m"])


def rho(err: np.ndarray, lag: int) -> float:
    """Horizontal autocorrelation of ``err`` at ``lag`` px (finite pixels only)."""
    a, b = err[:, :-lag], err[:, lag:]
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok] - a[ok].mean(), b[ok] - b[ok].mean()
    return float((a * b).mean() / np.sqrt((a * a).mean() * (b * b).mean()))


def plane_errors(name: str | None, scale: float, z_m: float, *, frames: int = 3) -> np.ndarray:
    """Depth errors (m) of the profile (None: the built-in model) on a textured fronto-parallel
    plane at ``z_m`` seen by the lq-hq rig's LQ camera at ``scale`` (the noise as the rig builds it)."""
    spec = build_rig("lq-hq", scale=scale, lq_profile=name).sensor("lq")
    K: Intrinsics = spec.depth
    rays = K.ray_grid()[..., 0].astype(np.float32)
    out = []
    for i in range(frames):
        rng = np.random.default_rng([7, i])
        z = np.full(K.shape, z_m, np.float32)
        lum = rng.uniform(0.3, 0.7, K.shape).astype(np.float32)
        nd = stereo_depth(z, rays, lum, noise=spec.noise, fx=K.fx, cx=K.cx, rng=rng)
        out.append(nd.depth - z)
    return np.stack(out)


@pytest.mark.parametrize("name", ["D435", "D415"])
def test_profile_depth_error_is_the_real_sensors_at_any_scale(name):
    z = 1.5
    expected = sigma_native(name, z)
    for scale in (1.0, 0.25):
        err = plane_errors(name, scale, z, frames=1 if scale == 1 else 4)
        # the profile's far outliers (uniform in depth, 0.25 % for the D435) are not the Gaussian part
        err = err[np.isfinite(err) & (np.abs(err) < 6 * expected)]
        assert abs(float(err.std()) / expected - 1) < 0.10, (name, scale, float(err.std()), expected)


def test_profile_correlation_is_in_native_pixels():
    p, f = native("D435")
    for scale in (1.0, 0.25):
        spec = build_rig("lq-hq", scale=scale, lq_profile="D435").sensor("lq")
        s_img = p["correlation_px"] * spec.depth.fx / f      # Gaussian blur width in image px
        err = plane_errors("D435", scale, 1.2, frames=1 if scale == 1 else 4)
        err = np.where(np.abs(err) < 6 * sigma_native("D435", 1.2), err, np.nan)
        for lag in (1, 3):
            # blurred white noise: rho(lag) = exp(-lag^2 / (4 s^2)); the 1/32 px step lowers it a little
            assert abs(np.nanmean([rho(e, lag) for e in err]) - np.exp(-lag ** 2 / (4 * s_img ** 2))) < 0.06, \
                (scale, lag, s_img)


def test_hq_profile_tof_error_and_correlation():
    p, f = native("Azure Kinect")
    spec = build_rig("lq-hq", scale=1.0, hq_profile="Azure Kinect").sensor("hq")  # blur 1.1 px
    K = spec.depth
    z = np.full(K.shape, 2.0, np.float32)
    errs = [tof_depth(z, np.full(K.shape, 0.6, np.float32), noise=spec.noise, rng=np.random.default_rng(i)).depth - z
            for i in range(6)]
    e = np.concatenate([x[np.isfinite(x) & (np.abs(x) < 0.05)] for x in errs])
    assert abs(float(e.std()) / (p["sigma_slope"] * 2.0) - 1) < 0.10
    s_img = p["correlation_px"] * K.fx / f
    measured = np.mean([rho(np.where(np.abs(x) < 0.05, x, np.nan), 1) for x in errs])
    assert abs(measured - np.exp(-1 / (4 * s_img ** 2))) < 0.06, (measured, s_img)


def test_default_rig_keeps_its_depth_error_at_any_scale():
    """Without a profile: the built-in model at scale 1 (0.08 px at the LQ camera's 600 px), and at
    a smaller scale the same depth error on a plane, ``z**2 hypot(0.08, (1/32) / sqrt 12) / (600 px * 55 mm)``
    (the built-in numbers by hand), not the scale-1 pixel noise in the smaller image's pixels."""
    full = build_rig("lq-hq", scale=1.0)
    assert full.sensor("lq").noise == StereoNoise() and full.sensor("hq").noise == TofNoise()
    for sensor in ("lq", "hq"):
        spec = build_rig("lq-hq", scale=0.25).sensor(sensor)
        assert spec.profile == "" and "profile" not in spec.noise_dict()
    z = 1.5
    expected = z ** 2 * float(np.hypot(0.08, (1 / 32) / np.sqrt(12))) / (600.0 * 0.055)   # 3.05 mm
    for scale, frames in ((1.0, 1), (0.5, 2), (0.25, 4)):
        err = plane_errors(None, scale, z, frames=frames)
        err = err[np.isfinite(err) & (np.abs(err) < 0.05)]
        assert abs(float(err.std()) / expected - 1) < 0.10, (scale, float(err.std()), expected)


def test_simulate_records_the_profile_and_diagnose_recovers_it(tmp_path, capfd):
    from bench.diagnose.core import diagnose_sensor
    from bench.diagnose.sources import load

    out = tmp_path / "s"
    r = run_inproc(capfd, "capture", "simulate", "--out", out, "--rig", "lq-hq", "--scene", "planes",
                   "--seconds", "0.2", "--scale", "0.5", "--lq-profile", "D415", "--hq-profile", "Azure Kinect",
                   "--no-progress")
    assert r.returncode == 0, r.stderr
    manifest = json.loads((out / "session.json").read_text())
    truth = json.loads((out / "truth" / "truth.json").read_text())
    for sensors in (manifest["sensors"], truth["sensors"]):
        assert sensors["lq"]["noise"]["profile"]["name"] == "D415"
        assert sensors["hq"]["noise"]["profile"]["name"] == "Azure Kinect"
    lq = next(s for s in load(out, max_frames=12) if s.sensor == "lq")
    d = diagnose_sensor(lq)
    assert any("D415" in n for n in d.notes)
    ok = np.isfinite(d.sigma.sigma) & (d.sigma.count > 2000)
    assert ok.sum() >= 2
    # the prediction per depth bin: the RMS of the native formula over the bin's pixels (their true
    # depths, as diagnose bins them; a bin's pixels need not sit at its centre: the nearest plane of
    # the scene fills only part of the first bin), a noise floor in the profile added in quadrature
    floor = native("D415")[0]["noise_floor_m"]
    ref, dep = np.stack(lq.reference), np.stack(lq.depth)
    z = ref[np.isfinite(ref) & np.isfinite(dep)]
    c = d.sigma.centre
    w = np.diff(c).mean()
    which = np.digitize(z, np.r_[c - w / 2, c[-1] + w / 2]) - 1
    pred = np.array([np.sqrt(np.mean(np.hypot(sigma_native("D415", z[which == b]), floor) ** 2))
                     for b in np.flatnonzero(ok)])
    ratio = d.sigma.sigma[ok] / pred
    assert abs(np.median(ratio) - 1) < 0.05 and np.all(np.abs(ratio - 1) < 0.20), (d.sigma.centre[ok], ratio)
    # and not the default LQ model (0.08 px at 600 px, i.e. 0.04 px at this image's 300 px): the
    # measured error is much closer to the profile's prediction than to the default's
    default = StereoNoise().sigma_z(d.sigma.centre[ok], 600.0)
    assert np.median(np.abs(ratio - 1)) < 0.5 * np.median(np.abs(d.sigma.sigma[ok] / default - 1)), default


def test_unknown_or_mismatched_profile_is_a_one_line_error(tmp_path, capfd):
    for args, words in ((["--lq-profile", "D999"], ("--lq-profile", "D999", "D435")),
                        (["--hq-profile", "D435"], ("--hq-profile", "tof", "Azure Kinect")),
                        (["--lq-profile", "Azure Kinect"], ("--lq-profile", "stereo"))):
        r = run_inproc(capfd, "capture", "simulate", "--out", tmp_path / "x", "--seconds", "0.1", *args)
        assert r.returncode == 2 and r.stdout == "" and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert all(w in r.stderr for w in words), r.stderr
        assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("name", sorted(PROFILES))
def test_each_profile_brings_its_twin_closer_without_a_statistic_worse(name):
    """The stored sim-to-real distances (``bench diagnose --sim-to-real`` on the real capture, written
    by ``python -m bench.diagnose.profiles``): means over three twins, and from the simulator's
    default sensor to the kept model no statistic grows beyond the stage rule's allowance, while
    the random error's distance (sigma) shrinks by more than its standard errors."""
    from bench.diagnose.twin import worse_statistics

    prov = PROFILES[name]["provenance"]
    assert prov["twin_seeds"] == [0, 1, 2]
    stages = list(prov["distances"])
    before, after = prov["distances"][stages[0]], prov["distances"][prov["kept_stage"]]
    assert worse_statistics(before, after) == [], (before, after)
    se = prov["distance_standard_errors"]
    assert after["sigma_m"] + 2 * se[prov["kept_stage"]]["sigma_m"] < before["sigma_m"] - 2 * se[stages[0]]["sigma_m"]
