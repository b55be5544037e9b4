"""Scenes for the simulator: a room, walking articulated figures, drifting balloons, planes.

Pure numpy, no I/O. World frame: metres, z up, floor at z = 0; the rigs stand near the
origin and look along +y into the room. A scene is a fixed set of rigid *parts* (triangle
meshes in their own local frame, each with a material) grouped into *actors* whose poses are
functions of scene time. :meth:`Scene.vertices_at` gives all vertices in world coordinates
at one instant; the triangles, the rest-pose (local) vertices and the materials never change,
which is what lets the texture stay fixed to each surface.

Scenes (``SCENES``):

* ``people``: three figures walking elliptical paths at about 1 m/s, turning continuously, plus
  three drifting balloons; the figures are smooth and body-like: tapered body segments with
  hemispherical ends and an ellipsoidal head, swinging arms and legs, shaded with interpolated
  vertex normals (no facets for a network to learn; the render test measures the shading
  normal's error);
* ``people-boxy``: the same walks and balloons with the earlier figures (capsules, boxes and a
  sphere head, flat-shaded facets), kept to compare against (``perf/simulate_fps.py``);
* ``balloons``: eight textured balloons drifting and spinning;
* ``planes``: fronto-parallel textured panels 1.0, 1.5, 2.0, 2.5 and 3.0 m in front of the
  origin (plus the back wall at 4.5 m), sliding sideways by a few centimetres.

``static=True`` freezes every actor at t = 0 (the time shift between sensors is then
unobservable, which alignment must be able to say).

Example:
    >>> s = build_scene("planes", seed=0)
    >>> v0, v1 = s.vertices_at(0.0), s.vertices_at(0.5)
    >>> v0.shape == v1.shape == s.rest_vertices.shape, bool((v0 != v1).any())
    (True, True)
    >>> bool((build_scene("planes", seed=0, static=True).vertices_at(0.5) == v0).all())
    True
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from capture.sim.errors import SimulationError
from capture.sim.geometry import _lathe, box, capsule, pose, quad, rot_x, rot_y, rot_z, sphere
from capture.sim.texture import Material

SCENES = ("people", "people-boxy", "balloons", "planes")

#: Back wall distance (y, metres) per scene; the planes scene documents its depths exactly.
PLANE_DEPTHS_M = (1.0, 1.5, 2.0, 2.5, 3.0)
PLANES_WALL_M = 4.5


@dataclass
class Part:
    """A rigid triangle mesh in its local frame (metres) with a material id. ``smooth``: shade
    with normals interpolated from the vertices (curved bodies) instead of the facets' normals."""

    vertices: np.ndarray
    triangles: np.ndarray
    material: int
    smooth: bool = False


@dataclass
class Actor:
    """Parts that move together; ``poses(t_s)`` returns one 4x4 ``T_world_part`` per part.
    ``moving=False`` promises the poses never change (the renderer caches what it sees)."""

    name: str
    parts: list[Part]
    poses: Callable[[float], list[np.ndarray]]
    moving: bool = True


@dataclass
class Scene:
    """All actors of a scene, flattened into one triangle soup for ray casting."""

    name: str
    actors: list[Actor]
    materials: dict[int, Material] = field(default_factory=dict)
    static: bool = False

    def __post_init__(self) -> None:
        # Still actors first: their triangles are a prefix, so a cast of the still part alone
        # numbers triangles as the full scene does.
        self.actors = sorted(self.actors, key=lambda a: a.moving and not self.static)
        parts = [p for a in self.actors for p in a.parts]
        counts = [len(p.vertices) for p in parts]
        self._offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.rest_vertices = np.concatenate([p.vertices for p in parts]).astype(np.float32)
        self.triangles = np.concatenate(
            [p.triangles + o for p, o in zip(parts, self._offsets[:-1])]).astype(np.uint32)
        self.triangle_material = np.concatenate(
            [np.full(len(p.triangles), p.material, dtype=np.int32) for p in parts])
        self.triangle_smooth = np.concatenate([np.full(len(p.triangles), p.smooth) for p in parts])
        #: the part (index into the flattened parts) each triangle belongs to
        self.triangle_part = np.repeat(np.arange(len(parts), dtype=np.int32), [len(p.triangles) for p in parts])
        self.rest_normals = np.concatenate([vertex_normals(p.vertices, p.triangles) if p.smooth
                                            else np.zeros_like(p.vertices) for p in parts]).astype(np.float32)
        still = [a for a in self.actors if not a.moving or self.static]
        self.n_still_parts = sum(len(a.parts) for a in still)
        self.n_still_triangles = sum(len(p.triangles) for a in still for p in a.parts)
        self.n_still_vertices = int(self._offsets[self.n_still_parts])

    def moving_part_bounds(self, vertices: np.ndarray) -> np.ndarray:
        """Axis-aligned world bounds ``(P, 2, 3)`` (min, max) of every moving part, given
        :meth:`vertices_at`'s output."""
        starts = self._offsets[self.n_still_parts:-1]
        if len(starts) == 0:
            return np.zeros((0, 2, 3), np.float32)
        lo = np.minimum.reduceat(vertices, starts, axis=0)
        hi = np.maximum.reduceat(vertices, starts, axis=0)
        return np.stack([lo, hi], axis=1)

    def part_poses(self, t_s: float) -> list[np.ndarray]:
        """``T_world_part`` (4x4) of every part, in the order of :attr:`rest_vertices`."""
        t = 0.0 if self.static else float(t_s)
        return [T for a in self.actors for T in a.poses(t)]

    def vertices_at(self, t_s: float) -> np.ndarray:
        """World coordinates ``(V, 3)`` float32 of every vertex at scene time ``t_s`` seconds."""
        out = np.empty_like(self.rest_vertices)
        for T, a, b in zip(self.part_poses(t_s), self._offsets[:-1], self._offsets[1:]):
            out[a:b] = self.rest_vertices[a:b] @ T[:3, :3].T.astype(np.float32) + T[:3, 3].astype(np.float32)
        return out

    @property
    def has_smooth(self) -> bool:
        return bool(self.triangle_smooth.any())

    def normals_at(self, t_s: float) -> np.ndarray:
        """World unit normals ``(V, 3)`` float32 of the vertices of smooth parts at ``t_s`` (zero elsewhere)."""
        out = np.zeros_like(self.rest_normals)
        for T, a, b in zip(self.part_poses(t_s), self._offsets[:-1], self._offsets[1:]):
            if self.rest_normals[a:b].any():
                out[a:b] = self.rest_normals[a:b] @ T[:3, :3].T.astype(np.float32)
        return out


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area-weighted unit normals ``(V, 3)`` of a closed mesh's vertices (outward for the
    counter-clockwise triangles of :mod:`capture.sim.geometry`).

    >>> from capture.sim.geometry import sphere
    >>> v, t = sphere(1.0)
    >>> n = vertex_normals(v, t)
    >>> bool(np.all(np.sum(n * v, axis=1) > 0.99))
    True
    """
    v = np.asarray(vertices, np.float64)
    f = np.cross(v[triangles[:, 1]] - v[triangles[:, 0]], v[triangles[:, 2]] - v[triangles[:, 0]])
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, triangles[:, k], f)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return (n / np.maximum(norm, 1e-12)).astype(np.float32)


# ----------------------------------------------------------------------------- room
class _Ids:
    """Hands out material ids and remembers their patterns."""

    def __init__(self) -> None:
        self.materials: dict[int, Material] = {}

    def new(self, material: Material | None = None) -> int:
        mid = len(self.materials) + 1
        self.materials[mid] = material or Material()
        return mid


def _static_actor(name: str, parts: list[Part], poses: list[np.ndarray]) -> Actor:
    return Actor(name, parts, lambda t, _p=poses: _p, moving=False)


def _room(ids: _Ids, *, back_y: float, half_width: float = 2.8, height: float = 3.0) -> Actor:
    floor_mat = ids.new(Material(fine_m=0.05, coarse_m=0.25, patch_m=0.8, dark_fraction=0.04, flat_fraction=0.04))
    wall_mat = [ids.new(Material(fine_m=0.06, coarse_m=0.3, patch_m=0.7, dark_fraction=0.06, flat_fraction=0.08))
                for _ in range(3)]
    depth = back_y + 1.5
    parts = [Part(*quad(2 * half_width, depth), floor_mat),
             Part(*quad(2 * half_width, height), wall_mat[0]),
             Part(*quad(depth, height), wall_mat[1]),
             Part(*quad(depth, height), wall_mat[2])]
    poses = [pose(None, (0.0, back_y - depth / 2, 0.0)),                           # floor, facing up
             pose(rot_x(np.pi / 2), (0.0, back_y, height / 2)),                    # back wall, facing -y
             pose(rot_z(-np.pi / 2) @ rot_x(np.pi / 2), (-half_width, back_y - depth / 2, height / 2)),
             pose(rot_z(np.pi / 2) @ rot_x(np.pi / 2), (half_width, back_y - depth / 2, height / 2))]
    return _static_actor("room", parts, poses)


def _props(ids: _Ids, back_y: float) -> Actor:
    """Static furniture: a cabinet against the back wall and a low table, for static features."""
    parts = [Part(*box((0.9, 0.45, 1.6)), ids.new(Material(fine_m=0.05, coarse_m=0.2))),
             Part(*box((1.0, 0.6, 0.7)), ids.new(Material(fine_m=0.03, coarse_m=0.12)))]
    poses = [pose(rot_z(0.1), (-1.9, back_y - 0.35, 0.8)), pose(rot_z(-0.3), (1.9, back_y - 1.2, 0.35))]
    return _static_actor("props", parts, poses)


# ----------------------------------------------------------------------------- figures
_BODY = {  # name: (radius, length, joint in figure frame (x fwd, y left, z up))
    "torso": (0.17, 0.62, (0.0, 0.0, 1.50)),
    "upper_leg_l": (0.075, 0.46, (0.0, 0.10, 0.93)), "upper_leg_r": (0.075, 0.46, (0.0, -0.10, 0.93)),
    "lower_leg_l": (0.06, 0.48, None), "lower_leg_r": (0.06, 0.48, None),
    "upper_arm_l": (0.05, 0.30, (0.0, 0.24, 1.43)), "upper_arm_r": (0.05, 0.30, (0.0, -0.24, 1.43)),
    "lower_arm_l": (0.045, 0.28, None), "lower_arm_r": (0.045, 0.28, None),
}


@dataclass(frozen=True)
class Walk:
    """An elliptical walking path: centre (x, y), radii (m), speed (m/s), start angle, direction."""

    cx: float
    cy: float
    rx: float
    ry: float
    speed: float
    phase: float
    direction: int

    def at(self, t: float) -> tuple[np.ndarray, float, float]:
        """(position (2,), heading yaw rad, gait phase rad) at ``t`` seconds."""
        omega = self.direction * self.speed / (0.5 * (self.rx + self.ry))
        a = self.phase + omega * t
        p = np.array([self.cx + self.rx * np.cos(a), self.cy + self.ry * np.sin(a)])
        v = np.array([-self.rx * np.sin(a), self.ry * np.cos(a)]) * omega
        gait = 2 * np.pi * (self.speed / 1.3) * t + self.phase
        return p, float(np.arctan2(v[1], v[0])), gait


#: radius at the far end over radius at the joint: limbs taper towards wrists and ankles
_TAPER = {"torso": 0.85, "upper_leg": 0.8, "lower_leg": 0.7, "upper_arm": 0.85, "lower_arm": 0.75}


def tapered_limb(r_top: float, r_bottom: float, length: float, *, segments: int = 12,
                 cap_rings: int = 3, body_rings: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A closed body segment from z = 0 down to z = -length: a hemisphere of ``r_top`` at the joint,
    a cone to ``r_bottom``, a hemisphere of ``r_bottom`` at the far end (a capsule when the radii
    are equal). Shaded smooth, it has no visible facets or seams.

    >>> v, t = tapered_limb(0.1, 0.05, 0.5)
    >>> round(float(v[:, 2].max()), 6), round(float(v[:, 2].min()), 6)
    (0.0, -0.5)
    """
    th = np.linspace(0, np.pi / 2, cap_rings + 1)
    bottom_r, bottom_z = r_bottom * np.sin(th), -length + r_bottom - r_bottom * np.cos(th)
    s = np.linspace(0, 1, body_rings + 2)[1:-1]
    mid_r = r_bottom + (r_top - r_bottom) * s
    mid_z = (-length + r_bottom) + ((-r_top) - (-length + r_bottom)) * s
    top_r, top_z = r_top * np.cos(th), -r_top + r_top * np.sin(th)
    return _lathe(np.concatenate([bottom_r, mid_r, top_r]), np.concatenate([bottom_z, mid_z, top_z]), segments)


def _figure_parts(ids: _Ids, rng: np.random.Generator, *, smooth: bool) -> list[Part]:
    """``smooth``: body-like segments (tapered, smooth-shaded) and an ellipsoidal head; else
    capsules and a sphere with facet shading (the original ``people``)."""
    parts = []
    for name, (r, length, _) in _BODY.items():
        if smooth:
            v, t = tapered_limb(r, r * _TAPER[name.rsplit("_", 1)[0] if name != "torso" else "torso"], length)
        else:
            v, t = capsule(r, length)
        if name == "torso":
            v = v * np.array([0.75, 1.15, 1.0])
        parts.append(Part(v, t, ids.new(Material(fine_m=float(rng.uniform(0.02, 0.04)), coarse_m=0.1,
                                                 patch_m=0.25, dark_fraction=0.1, flat_fraction=0.05)), smooth=smooth))
    hv, ht = sphere(0.11, segments=16, rings=8)
    if smooth:
        hv = hv * np.array([0.9, 0.82, 1.08])
    parts.append(Part(hv, ht, ids.new(Material(fine_m=0.03, dark_fraction=0.0)), smooth=smooth))
    return parts


def _figure_poses(walk: Walk, t: float) -> list[np.ndarray]:
    p, yaw, g = walk.at(t)
    root = pose(rot_z(yaw), (p[0], p[1], 0.02 * abs(np.sin(g))))
    hip = 0.45 * np.sin(g)
    knee_l, knee_r = 0.7 * max(0.0, np.sin(g + 1.2)), 0.7 * max(0.0, np.sin(g + 1.2 + np.pi))
    shoulder = 0.35 * np.sin(g)
    poses = {"torso": root @ pose(None, _BODY["torso"][2])}
    for side, sgn in (("l", 1.0), ("r", -1.0)):
        upper_leg = root @ pose(rot_y(-sgn * hip), _BODY[f"upper_leg_{side}"][2])
        knee = knee_l if side == "l" else knee_r
        poses[f"upper_leg_{side}"] = upper_leg
        poses[f"lower_leg_{side}"] = upper_leg @ pose(rot_y(knee), (0.0, 0.0, -0.44))
        upper_arm = root @ pose(rot_y(sgn * shoulder) @ rot_x(sgn * 0.08), _BODY[f"upper_arm_{side}"][2])
        poses[f"upper_arm_{side}"] = upper_arm
        poses[f"lower_arm_{side}"] = upper_arm @ pose(rot_y(-0.35), (0.0, 0.0, -0.28))
    head = root @ pose(rot_z(0.2 * np.sin(0.5 * g)), (0.0, 0.0, 1.66))
    return [poses[name] for name in _BODY] + [head]


def _figure(ids: _Ids, rng: np.random.Generator, walk: Walk, name: str, *, smooth: bool) -> Actor:
    return Actor(name, _figure_parts(ids, rng, smooth=smooth), lambda t, w=walk: _figure_poses(w, t))


# ----------------------------------------------------------------------------- balloons
@dataclass(frozen=True)
class Drift:
    """Sinusoidal drift about a centre plus a spin about an axis."""

    centre: tuple
    amplitude: tuple
    omega: tuple
    phase: tuple
    spin_axis: tuple
    spin_rate: float

    def pose(self, t: float) -> np.ndarray:
        from scipy.spatial.transform import Rotation

        c = np.asarray(self.centre) + np.asarray(self.amplitude) * np.sin(np.asarray(self.omega) * t + self.phase)
        R = Rotation.from_rotvec(np.asarray(self.spin_axis) * self.spin_rate * t).as_matrix()
        return pose(R, c)


def _balloon(ids: _Ids, rng: np.random.Generator, name: str, *, region, amplitude, smooth: bool = False) -> Actor:
    radius = float(rng.uniform(0.12, 0.2))
    lo, hi = np.asarray(region[0]), np.asarray(region[1])
    axis = rng.normal(size=3)
    drift = Drift(tuple(rng.uniform(lo, hi)), tuple(rng.uniform(0.3, 1.0, 3) * amplitude),
                  tuple(rng.uniform(0.4, 1.2, 3)), tuple(rng.uniform(0, 2 * np.pi, 3)),
                  tuple(axis / np.linalg.norm(axis)), float(rng.uniform(0.3, 0.9)))
    part = Part(*sphere(radius), ids.new(Material(fine_m=0.025, coarse_m=0.08, patch_m=0.2,
                                                  dark_fraction=0.05, flat_fraction=0.05)), smooth=smooth)
    return Actor(name, [part], lambda t, d=drift: [d.pose(t)])


# ----------------------------------------------------------------------------- panels
def _panel_actor(ids: _Ids, rng: np.random.Generator, *, eye_height: float) -> Actor:
    parts, base, motion = [], [], []
    for i, d in enumerate(PLANE_DEPTHS_M):
        angle = -0.34 + 0.17 * i
        w, h = 0.14 * d, 0.32 * d
        parts.append(Part(*quad(w, h), ids.new(Material(fine_m=0.012 * d, coarse_m=0.05 * d, dark_fraction=0.0,
                                                        flat_fraction=0.0))))
        base.append((d * np.tan(angle), d, eye_height + (0.05 if i % 2 else -0.05) * d))
        motion.append((0.04 * d * 0.5, float(rng.uniform(0, 2 * np.pi))))

    def poses(t: float) -> list[np.ndarray]:
        return [pose(rot_x(np.pi / 2), (x + a * np.sin(2 * np.pi * t / 3.0 + ph), y, z))
                for (x, y, z), (a, ph) in zip(base, motion)]

    return Actor("panels", parts, poses)


# ----------------------------------------------------------------------------- builder
def build_scene(name: str, *, seed: int = 0, static: bool = False, eye_height: float = 1.3) -> Scene:
    """Build scene ``name`` (one of :data:`SCENES`); ``seed`` fixes paths, sizes and patterns."""
    if name not in SCENES:
        raise SimulationError(f"--scene: unknown scene {name!r} (choose from {', '.join(SCENES)})")
    rng = np.random.default_rng([int(seed), 101])
    ids = _Ids()
    if name == "planes":
        actors = [_room(ids, back_y=PLANES_WALL_M), _panel_actor(ids, rng, eye_height=eye_height)]
        return Scene(name, actors, ids.materials, static)
    actors = [_room(ids, back_y=5.0), _props(ids, 5.0)]
    if name in ("people", "people-boxy"):
        smooth = name == "people"
        for k, cy in enumerate((2.0, 2.9, 3.7)):
            walk = Walk(float(rng.uniform(-0.4, 0.4)), cy, float(rng.uniform(0.7, 1.0)), 0.33,
                        float(rng.uniform(0.85, 1.2)), float(rng.uniform(0, 2 * np.pi)), int(rng.choice([-1, 1])))
            actors.append(_figure(ids, rng, walk, f"figure{k}", smooth=smooth))
        for k in range(3):
            actors.append(_balloon(ids, rng, f"balloon{k}", region=((-1.4, 1.4, 1.9), (1.4, 4.2, 2.5)),
                                   amplitude=0.25, smooth=smooth))
    else:
        for k in range(8):
            actors.append(_balloon(ids, rng, f"balloon{k}", region=((-1.2, 1.3, 0.5), (1.2, 3.8, 2.2)),
                                   amplitude=0.4))
    return Scene(name, actors, ids.materials, static)
