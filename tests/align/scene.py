"""A tiny analytic ray caster for tests: planes, rectangles and spheres seen by any camera.

Independent of the warp and of the simulator: depth and colour are computed per pixel from the
exact ray/surface intersections, so they are the truth the alignment code is checked against.
Shapes are in world coordinates (metres); ``T_cam_world`` maps world points into the camera.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from capture.camera import Intrinsics, Transform


@dataclass
class Plane:
    point: tuple
    normal: tuple


@dataclass
class Rect:
    """A finite plane patch: centre, two half-axis vectors (they span the patch)."""
    centre: tuple
    half_u: tuple
    half_v: tuple


@dataclass
class Sphere:
    centre: tuple
    radius: float


def _intersect(origin, dirs, shape):
    """Ray parameter t (dirs not normalised) of the first hit, inf where none. origin (3,), dirs (N, 3)."""
    o = np.asarray(origin, float)
    if isinstance(shape, Plane):
        n, p0 = np.asarray(shape.normal, float), np.asarray(shape.point, float)
        den = dirs @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((p0 - o) @ n) / den
        return np.where((t > 1e-9) & np.isfinite(t), t, np.inf)
    if isinstance(shape, Rect):
        c, hu, hv = (np.asarray(x, float) for x in (shape.centre, shape.half_u, shape.half_v))
        n = np.cross(hu, hv)
        den = dirs @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((c - o) @ n) / den
        P = o + dirs * t[:, None]
        a = (P - c) @ hu / (hu @ hu)
        b = (P - c) @ hv / (hv @ hv)
        hit = (t > 1e-9) & (np.abs(a) <= 1) & (np.abs(b) <= 1)
        return np.where(hit, t, np.inf)
    if isinstance(shape, Sphere):
        c, r = np.asarray(shape.centre, float), shape.radius
        oc = o - c
        A = np.einsum("ij,ij->i", dirs, dirs)
        B = 2 * dirs @ oc
        C = oc @ oc - r * r
        disc = B * B - 4 * A * C
        with np.errstate(invalid="ignore"):
            t = (-B - np.sqrt(disc)) / (2 * A)
        return np.where((disc >= 0) & (t > 1e-9), t, np.inf)
    raise TypeError(shape)


def cast(K: Intrinsics, T_cam_world: Transform, shapes):
    """Per pixel: z-depth (H, W) float64 (NaN = nothing), world points (H, W, 3), shape index (H, W)."""
    rays_cam = K.ray_grid().reshape(-1, 3)  # z = 1, distortion honoured
    T_world_cam = T_cam_world.inverse()
    origin = T_world_cam.t
    dirs = rays_cam @ T_world_cam.R.T
    ts = np.stack([_intersect(origin, dirs, s) for s in shapes], axis=1)
    which = np.argmin(ts, axis=1)
    t = ts[np.arange(ts.shape[0]), which]
    hit = np.isfinite(t)
    depth = np.where(hit, t, np.nan)  # rays have z = 1 in the camera, so t is the z-depth
    P = origin + dirs * np.where(hit, t, 0)[:, None]
    return depth.reshape(K.shape), P.reshape(*K.shape, 3), np.where(hit, which, -1).reshape(K.shape)


def texture(P: np.ndarray, seed: int = 0) -> np.ndarray:
    """A colour fixed to the surfaces: random blocks at three scales, RGB uint8 (H, W, 3)."""
    out = np.zeros(P.shape[:-1] + (3,), float)
    for scale, weight in ((0.05, 0.5), (0.021, 0.3), (0.0093, 0.2)):
        cell = np.floor(np.nan_to_num(P) / scale).astype(np.int64)
        h = (cell[..., 0] * 73856093) ^ (cell[..., 1] * 19349663) ^ (cell[..., 2] * 83492791) ^ (seed * 2654435761)
        for c in range(3):
            out[..., c] += weight * (((h >> (8 * c + 3)) & 255) / 255.0)
    return np.clip(out * 255, 0, 255).astype(np.uint8)


def look_at(eye, target, up=(0, -1, 0)) -> Transform:
    """T_cam_world of a camera at ``eye`` looking at ``target`` (x right, y down, z forward)."""
    eye, target, up = (np.asarray(x, float) for x in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R_world_cam = np.stack([x, y, z], axis=1)
    return Transform.from_rt(R_world_cam, eye).inverse()


def room(person_at=(0.0, 0.2, 2.2)):
    """Back wall at z = 4.5, floor at y = 1.2 (y down), a side wall, a 'person' slab and a ball."""
    px, py, pz = person_at
    return [
        Plane((0, 0, 4.5), (0, 0, 1)),
        Plane((0, 1.2, 0), (0, 1, 0)),
        Plane((-2.2, 0, 0), (1, 0, 0)),
        Rect((px, py, pz), (0.25, 0, 0.05), (0, 0.8, 0)),
        Sphere((px + 0.8, py - 0.3, pz + 0.6), 0.25),
    ]
