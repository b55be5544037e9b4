"""Smooth bodies: the simulated people's shading normals follow the curved surface (no facets
a network could learn), flat parts keep their facet normals, and the limbs are closed, tapered
surfaces."""
from __future__ import annotations

import numpy as np

from capture.camera import Intrinsics
from capture.sim.geometry import pose, quad, rot_x, sphere
from capture.sim.render import Renderer, camera_rays
from capture.sim.rigs import look_at
from capture.sim.scene import Actor, Part, Scene, build_scene, tapered_limb, vertex_normals
from capture.sim.texture import Material

CENTRE = np.array([0.0, 2.0, 1.3])


def _scene(smooth: bool) -> Scene:
    ball = Part(*sphere(0.4), 1, smooth=smooth)
    wall = Part(*quad(4.0, 3.0), 2)
    return Scene("t", [Actor("ball", [ball], lambda t: [pose(None, CENTRE)]),
                       Actor("wall", [wall], lambda t: [pose(rot_x(np.pi / 2), (0.0, 4.0, 1.5))], moving=False)],
                 {1: Material(), 2: Material()})


def _angles_deg(smooth: bool):
    scene = _scene(smooth)
    r = Renderer(scene, nthreads=1)
    cam = camera_rays(Intrinsics(160, 120, 150.0, 150.0, 79.5, 59.5), look_at((0.0, 0.0, 1.3), (0.0, 3.0, 1.3)))
    ans = r.cast_raw(cam, 0.0)
    n = r.hit_normals(ans)
    rays = cam.rays.reshape(120, 160, 6)
    p = rays[..., :3] + ans["t_hit"][..., None] * rays[..., 3:]
    on_ball = np.isfinite(ans["t_hit"]) & (np.linalg.norm(p - CENTRE, axis=-1) < 0.41)
    d = (p - CENTRE)[on_ball]  # rays that miss have no point (NaN)
    true = d / np.linalg.norm(d, axis=-1, keepdims=True)
    cos = np.abs(np.sum(n[on_ball] * true, axis=-1))
    wall = np.isfinite(ans["t_hit"]) & ~on_ball
    return np.degrees(np.arccos(np.clip(cos, -1, 1))), n[wall], ans["primitive_normals"][wall]


def test_smooth_parts_shade_with_the_surface_normal():
    smooth, wall_n, wall_facet = _angles_deg(True)
    faceted, _, _ = _angles_deg(False)
    # a 20 x 10 sphere: facet normals are off by up to 12 deg (median 6.7); interpolated ones by
    # under a degree except next to the poles' triangle fans
    assert np.median(faceted) > 4.0  # the test can fail
    assert np.median(smooth) < 1.0 and np.percentile(smooth, 95) < 2.0 and smooth.max() < 0.35 * faceted.max(), \
        (smooth.max(), np.median(smooth))
    assert np.array_equal(wall_n, wall_facet)  # flat parts: facet normals, unchanged


def test_vertex_normals_and_tapered_limbs_are_closed_and_outward():
    v, t = tapered_limb(0.1, 0.06, 0.5)
    n = vertex_normals(v, t)
    # a closed surface: every edge is shared by exactly two triangles
    e = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    assert np.all(counts == 2)
    axis_point = np.c_[np.zeros((len(v), 2)), np.clip(v[:, 2], -0.44, -0.1)]
    assert np.all(np.sum(n * (v - axis_point), axis=1) > 0)  # outward
    r = np.hypot(v[:, 0], v[:, 1])
    assert abs(r[np.abs(v[:, 2] + 0.1) < 1e-9].max() - 0.1) < 1e-9  # top radius
    assert r.max() <= 0.1 + 1e-9 and v[:, 2].min() == -0.5


def test_smooth_people_scene():
    s = build_scene("people", seed=0)
    assert s.has_smooth
    figure = [a for a in s.actors if a.name.startswith("figure")][0]
    assert all(p.smooth for p in figure.parts)
    room = [a for a in s.actors if a.name == "room"][0]
    assert not any(p.smooth for p in room.parts)
    # same walks as 'people-boxy' (only the bodies differ): the figures' roots are at the same places
    p = build_scene("people-boxy", seed=0)
    assert not p.has_smooth
    assert np.allclose(s.part_poses(1.0)[0], p.part_poses(1.0)[0])
