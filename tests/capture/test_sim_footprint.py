"""The time-of-flight pixel footprint (``TofNoise.footprint_samples``, capture/sim/noise.py): the rays sit where the
sub-pixel formula puts them, the compiled reduction equals a direct loop, a slit thinner than one pixel step that the
point-sampled sensor cannot see reads as the footprint's mean, and the depth-only cast equals the shaded one."""
from __future__ import annotations

import numpy as np
import pytest

from capture.camera import Intrinsics, Transform
from capture.sim.errors import SimulationError
from capture.sim.noise import TofNoise, footprint_depth, tof_depth
from capture.sim.render import Renderer, camera_rays, footprint_rays, footprint_samples
from capture.sim.rigs import build_rig
from capture.sim.scene import build_scene


@pytest.mark.parametrize("distortion", [(), (-0.3, 0.05, 0.001, -0.002, 0.0)])
def test_footprint_rays_sit_at_the_sub_pixel_centres(distortion):
    K = Intrinsics(7, 5, 120.0, 118.0, 3.2, 2.1, "opencv" if distortion else "none", distortion)
    n = 4
    xy = footprint_rays(K, Transform.identity(), n).xy  # (5 n, 7 n, 2)
    x, y = footprint_samples(xy[..., 0], n), footprint_samples(xy[..., 1], n)  # (5, 7, 16) each
    for v, u in ((0, 0), (2, 3), (4, 6)):
        sub = np.array([[u + (i + 0.5) / n - 0.5, v + (j + 0.5) / n - 0.5] for j in range(n) for i in range(n)])
        expect = K.pixel_to_normalized(sub)
        np.testing.assert_allclose(x[v, u], expect[:, 0], atol=1e-6)
        np.testing.assert_allclose(y[v, u], expect[:, 1], atol=1e-6)


def _loop(footprint, amplitude):
    H, W, S = footprint.shape
    out = np.full((3, H, W), np.nan)
    for i in range(H):
        for j in range(W):
            z = [float(x) for x in footprint[i, j] if np.isfinite(x)]
            if z:
                w = [1 / x ** 2 if amplitude else 1.0 for x in z]
                out[:, i, j] = sum(a * b for a, b in zip(w, z)) / sum(w), min(z), max(z)
    return out


@pytest.mark.parametrize("mix", ["coverage", "coverage-amplitude"])
def test_footprint_depth_equals_a_direct_loop(mix):
    rng = np.random.default_rng(3)
    fp = rng.uniform(0.5, 6.0, (6, 9, 16)).astype(np.float32)
    fp[rng.random(fp.shape) < 0.3] = np.nan
    fp[0, 0] = np.nan  # a pixel whose rays all miss
    ref = _loop(fp, mix == "coverage-amplitude")
    np.testing.assert_allclose(np.stack(footprint_depth(fp, mix=mix)), ref, rtol=1e-5, equal_nan=True)
    got = tof_depth(np.fmin.reduce(fp, axis=-1), np.ones(fp.shape[:2], np.float32), rng=np.random.default_rng(0), footprint=fp,
                    noise=TofNoise(sigma0_m=0.0, sigma_slope=0.0, min_depth_m=0.1, flying_mix=mix, min_amplitude=0.0))
    flying = ref[2] - ref[1] > 0.05
    np.testing.assert_allclose(got.depth[flying], ref[0][flying], rtol=1e-5)  # the compiled path, as the loop
    assert np.array_equal(got.invalid["flying"], flying & np.isfinite(ref[0]))


def _slit_scene(n):
    """A near surface at 1 m with a 3 m slit 0.3 px wide inside pixel column 10's footprint, clear of its centre:
    the centres' depth and the footprints' (``n x n`` sub-samples, analytically)."""
    H, W = 6, 20
    x_sub = np.arange(W)[:, None] + (np.arange(n) + 0.5) / n - 0.5  # (W, n) sub-sample x, px
    in_slit = (x_sub > 10.1) & (x_sub < 10.4)
    fp = np.where(in_slit, 3.0, 1.0).astype(np.float32)  # (W, n)
    fp = np.broadcast_to(fp[None, :, None, :], (H, W, n, n)).reshape(H, W, n * n)
    return np.full((H, W), 1.0, np.float32), np.ascontiguousarray(fp)


def test_a_slit_between_point_samples_reads_as_a_mix_only_with_the_footprint():
    centre, fp = _slit_scene(4)
    noise = TofNoise(sigma0_m=0.0, sigma_slope=0.0, min_depth_m=0.1)
    point = tof_depth(centre, np.ones_like(centre), noise=noise, rng=np.random.default_rng(1))
    area = tof_depth(centre, np.ones_like(centre), noise=noise, rng=np.random.default_rng(1), footprint=fp)
    assert np.all(point.depth == 1.0)  # the point-sampled sensor sees no trace of the slit
    assert not point.invalid["flying"].any()
    # two of the four sub-sample columns of pixel 10 (x = 10.125, 10.375) lie in the slit: half covered
    np.testing.assert_allclose(area.depth[:, 10], 2.0, rtol=1e-6)
    assert area.invalid["flying"][:, 10].all() and not np.delete(area.invalid["flying"], 10, axis=1).any()
    np.testing.assert_array_equal(np.delete(area.depth, 10, axis=1), 1.0)


def test_footprint_samples_must_be_a_whole_number():
    with pytest.raises(SimulationError, match="footprint_samples"):
        TofNoise(footprint_samples=-1)
    with pytest.raises(SimulationError, match="footprint_samples"):
        TofNoise(footprint_samples=2.5)


def test_depth_only_cast_equals_the_shaded_cast():
    scene, rig = build_scene("people", seed=1), build_rig("lq-hq", scale=0.5)
    hq = rig.sensor("hq")
    fast, full = Renderer(scene, nthreads=1), Renderer(scene, nthreads=1, reuse_still=False)
    cam = footprint_rays(hq.depth, hq.T_world_depth, 2)
    for t in (0.0, 1.3):
        z = fast.cast_depth(cam, t)
        assert np.array_equal(z, full.cast(cam, t).z, equal_nan=True)
        assert np.array_equal(z, full.cast_depth(cam, t), equal_nan=True)
    # where a footprint's rays agree, their mean is the centre's depth; along silhouettes they straddle the jump
    centre = fast.cast(camera_rays(hq.depth, hq.T_world_depth), 1.3).z
    sub = footprint_samples(fast.cast_depth(cam, 1.3), 2)
    seen = np.isfinite(sub).all(-1) & np.isfinite(centre)  # the room has no ceiling: some rays meet nothing
    span = np.where(seen, sub.max(-1) - sub.min(-1), np.nan)
    flat = seen & (span < 0.02 * centre)  # one surface (sloped floors and walls included)
    assert flat.sum() > 0.9 * seen.sum() and (span[seen] > 0.3).sum() > 100
    off = (np.abs(sub.mean(-1) - centre) / centre)[flat]  # 1.5e-3 (mean) with the rays half a fine step off
    assert off.mean() < 1e-4 and np.quantile(off, 0.9) < 1e-4


@pytest.mark.parametrize("scene_name, scale", [("people", 0.5), ("people", 1.0), ("balloons", 0.5)])
def test_footprint_cast_near_part_edges_gives_the_full_casts_depth(scene_name, scale):
    """The footprint's rays are cast again only where a footprint can meet a moving part and span a jump; on the
    simulator's scenes the time-of-flight depth is exactly that of every ray cast again (the moving parts' whole
    bounding boxes), and the footprint equals the full cast's wherever its rays were cast."""
    from capture.sim.sensors import SensorCameras, _footprint

    scene, rig = build_scene(scene_name, seed=3), build_rig("lq-hq", scale=scale)
    hq = rig.sensor("hq")
    cams = SensorCameras.of(hq)
    r = Renderer(scene, nthreads=1)
    n = hq.noise.footprint_samples
    for t in (0.2, 1.1, 2.4):
        hits = r.cast(cams.depth, t)
        got = _footprint(r, cams, t, hits, jump_m=hq.noise.flying_jump_m)
        full = footprint_samples(r.cast_depth(cams.footprint, t), n)
        a, b = (tof_depth(hits.z, hits.albedo_luminance, noise=hq.noise, rng=np.random.default_rng(5), footprint=f)
                for f in (got, full))
        assert np.array_equal(a.depth, b.depth, equal_nan=True)
        assert np.array_equal(a.invalid["flying"], b.invalid["flying"])
        same = np.all((got == full) | (np.isnan(got) & np.isnan(full)), axis=-1)
        assert b.invalid["flying"][~same].sum() == 0  # every flying pixel's footprint was cast
    assert r.last_cast_pixels > 0  # the moving parts are in view
