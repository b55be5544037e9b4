"""Rendering: the compiled kernel equals the numpy texture reference, the still-layer fast path
equals casting every pixel, the texture is identical from two cameras, and it is rich enough
for feature matching."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from capture.camera import Intrinsics
from capture.sim.render import Renderer, camera_rays, reference_colors
from capture.sim.rigs import build_rig, look_at
from capture.sim.scene import build_scene
from capture.sim.texture import surface_color


@pytest.fixture(scope="module")
def people():
    return build_scene("people", seed=1), build_rig("lq-hq", scale=0.5)


def test_kernel_equals_numpy_reference(people):
    scene, rig = people
    r = Renderer(scene)
    s = rig.sensor("hq")
    cam = camera_rays(s.color, s.T_world_color)
    hits = r.cast(cam, 0.4, noise_dn=0.0)
    ref = reference_colors(r, r.cast_raw(cam, 0.4))
    ref8 = np.clip(np.rint(ref * 255), 0, 255).astype(np.int16)
    diff = np.abs(hits.rgb.astype(np.int16) - ref8).max(axis=-1)
    assert (diff <= 1).mean() > 0.999, (diff > 1).sum()


def test_still_layer_fast_path_equals_full_cast(people):
    scene, rig = people
    fast, full = Renderer(scene, nthreads=1), Renderer(scene, nthreads=1, reuse_still=False)
    lq = rig.sensor("lq")
    K = lq.depth
    distorted = Intrinsics(K.width, K.height, K.fx, K.fy, K.cx, K.cy, "opencv", (-0.3, 0.0, 0.0, 0.0, 0.0))
    for Ki, T in ((K, lq.T_world_depth), (distorted, lq.T_world_depth),
                  (rig.sensor("hq").color, rig.sensor("hq").T_world_color)):
        cam = camera_rays(Ki, T)
        for t in (0.0, 0.9, 2.3):
            a, b = fast.cast(cam, t, noise_seed=7, noise_dn=2.0), full.cast(cam, t, noise_seed=7, noise_dn=2.0)
            assert 0 < fast.last_cast_pixels < 0.6 * Ki.width * Ki.height  # the fast path is in use
            assert np.array_equal(a.z, b.z, equal_nan=True)
            # identical but for ties between touching surfaces (a box standing on the floor)
            assert (a.rgb != b.rgb).any(axis=-1).sum() <= 1e-4 * a.z.size


def test_texture_is_fixed_to_the_surface():
    p = np.random.default_rng(0).uniform(-1, 1, (1000, 3)).astype(np.float32)
    m = np.full(1000, 3)
    assert np.array_equal(surface_color(p, m), surface_color(p.copy(), m))
    assert not np.array_equal(surface_color(p, m), surface_color(p, m + 1))  # each material its own pattern


def _two_views(scene, t_s=0.5):
    """Noise-free colour and depth of the LQ camera and of a second camera 0.3 m to its right."""
    rig = build_rig("lq-hq")
    lq = rig.sensor("lq")
    other = look_at(lq.T_world_depth.t + [0.3, 0.0, 0.05], (0.3, 3.0, 0.9))
    r = Renderer(scene)
    a = r.cast(camera_rays(lq.depth, lq.T_world_depth), t_s)
    Kb = Intrinsics(640, 360, 353.0, 353.0, 319.5, 179.5)
    b = r.cast(camera_rays(Kb, other), t_s)
    return lq, a, Kb, other, b


def test_colour_identical_from_two_views():
    """Rays from a second camera aimed exactly at the surface points the LQ sees return the same colour."""
    scene = build_scene("people", seed=2)
    lq, a, Kb, T_wb, b = _two_views(scene)
    pts = lq.T_world_depth.apply(lq.depth.depth_to_points(a.z).reshape(-1, 3))
    ok = np.flatnonzero(np.isfinite(pts[:, 2]))[::7]
    d = pts[ok] - T_wb.t
    rays = np.concatenate([np.broadcast_to(T_wb.t, d.shape), d], axis=1).astype(np.float32)
    K1 = Intrinsics(len(rays), 1, 1.0, 1.0, 0.0, 0.0)  # a "camera" that is just this list of rays
    from capture.sim.render import CameraRays
    hits = Renderer(scene, reuse_still=False).cast(CameraRays(K1, T_wb, rays, np.zeros((1, len(rays), 2))), 0.5)
    seen = np.abs(hits.z[0] - 1.0) < 1e-3  # t = 1 is the point itself; smaller: something in front
    diff = np.abs(hits.rgb[0][seen].astype(int) - a.rgb.reshape(-1, 3)[ok][seen].astype(int)).max(axis=1)
    assert seen.sum() > 5000
    assert (diff <= 1).mean() > 0.995, np.percentile(diff, [50, 99, 99.9])


def test_texture_gives_many_feature_matches():
    scene = build_scene("people", seed=2)
    lq, a, Kb, T_wb, b = _two_views(scene)
    sift = cv2.SIFT_create()
    ka, da = sift.detectAndCompute(cv2.cvtColor(a.rgb, cv2.COLOR_RGB2GRAY), None)
    kb, db = sift.detectAndCompute(cv2.cvtColor(b.rgb, cv2.COLOR_RGB2GRAY), None)
    good = [m for m, n in cv2.BFMatcher().knnMatch(da, db, k=2) if m.distance < 0.75 * n.distance]
    # count matches that agree with the true geometry within 3 px
    correct = 0
    for m in good:
        u, v = ka[m.queryIdx].pt
        z = a.z[int(round(v)), int(round(u))]
        if not np.isfinite(z):
            continue
        p = lq.depth.unproject(np.array([[u, v]]), np.array([z]))
        q = Kb.project(T_wb.inverse().apply(lq.T_world_depth.apply(p)))[0]
        correct += np.hypot(*(q - kb[m.trainIdx].pt)) < 3
    assert correct > 300 and correct > 0.8 * len(good), (correct, len(good))


def test_depth_counts_kernel_equals_session_encoder():
    from capture.session import encode_depth
    from capture.sim.kernels import depth_counts
    rng = np.random.default_rng(0)
    d = (rng.random((48, 64)) * 8).astype(np.float32)
    d[rng.random(d.shape) < 0.1] = np.nan
    d[0, :6] = [-1, 0, 1e-5, 0.00049999, 70, np.inf]
    for unit in (0.001, 0.0001):
        assert np.array_equal(depth_counts(d, unit), encode_depth(d, unit))
