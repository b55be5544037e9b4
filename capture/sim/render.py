"""Batched ray casting of a scene with Open3D's ``RaycastingScene`` (one cast per image).

A :class:`Renderer` holds the scene's fixed triangles and rebuilds the Embree scene only
when asked for a new scene time (building a scene of ~20 k triangles takes about a
millisecond; the casts dominate). Viewing rays are computed once per camera
(:func:`camera_rays`, distortion included) and reused for every frame, since the rigs are static.

Depth convention: the ray of pixel ``(u, v)`` has direction ``(x, y, 1)`` in the camera frame,
so Open3D's ``t_hit`` *is* the z-depth in metres.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from capture.camera import Intrinsics, Transform
from capture.sim.scene import Scene
from capture.sim.texture import luminance, shade, surface_color

BACKGROUND_RGB = 0.08  # colour of rays that hit nothing


@dataclass(frozen=True)
class CameraRays:
    """Rays of one camera: ``rays`` ``(H, W, 6)`` float32 world origin+direction, and the
    undistorted normalised image coordinates ``xy`` ``(H, W, 2)`` in the camera frame."""

    intrinsics: Intrinsics
    T_world_cam: Transform
    rays: o3d.core.Tensor
    xy: np.ndarray


def camera_rays(K: Intrinsics, T_world_cam: Transform) -> CameraRays:
    """Rays through every pixel centre of ``K`` (lens distortion included) posed by ``T_world_cam``."""
    d_cam = K.ray_grid()  # (H, W, 3) with z = 1
    d_world = d_cam @ T_world_cam.R.T
    origin = np.broadcast_to(T_world_cam.t, d_world.shape)
    rays = np.concatenate([origin, d_world], axis=-1).astype(np.float32)
    return CameraRays(K, T_world_cam, o3d.core.Tensor(rays), d_cam[..., :2].astype(np.float32))


@dataclass
class Hits:
    """What one camera sees: ``z`` ``(H, W)`` float32 metres (NaN = nothing), ``albedo`` and
    ``shaded`` ``(H, W, 3)`` float32 RGB in [0, 1]."""

    z: np.ndarray
    albedo: np.ndarray
    shaded: np.ndarray


class Renderer:
    """Casts camera rays into a :class:`Scene` at a given scene time."""

    def __init__(self, scene: Scene, *, nthreads: int = 0) -> None:
        self.scene = scene
        self.nthreads = nthreads
        self._triangles = o3d.core.Tensor(scene.triangles)
        self._time: float | None = None
        self._rc: o3d.t.geometry.RaycastingScene | None = None

    def _scene_at(self, t_s: float) -> o3d.t.geometry.RaycastingScene:
        if self._rc is None or self._time != t_s:
            rc = o3d.t.geometry.RaycastingScene(nthreads=self.nthreads)
            rc.add_triangles(o3d.core.Tensor(self.scene.vertices_at(t_s)), self._triangles)
            self._rc, self._time = rc, t_s
        return self._rc

    def cast(self, cam: CameraRays, t_s: float, *, color: bool = True) -> Hits:
        """Cast ``cam``'s rays at scene time ``t_s`` seconds; texture the hits if ``color``."""
        ans = self._scene_at(t_s).cast_rays(cam.rays, nthreads=self.nthreads)
        t_hit = ans["t_hit"].numpy()
        hit = np.isfinite(t_hit)
        z = np.where(hit, t_hit, np.nan).astype(np.float32)
        H, W = z.shape
        albedo = np.full((H, W, 3), BACKGROUND_RGB, dtype=np.float32)
        shaded = albedo.copy()
        if color and hit.any():
            prim = ans["primitive_ids"].numpy()[hit]
            uv = ans["primitive_uvs"].numpy()[hit]
            tri = self.scene.triangles[prim]
            rest = self.scene.rest_vertices
            p_local = ((1 - uv[:, :1] - uv[:, 1:]) * rest[tri[:, 0]] + uv[:, :1] * rest[tri[:, 1]]
                       + uv[:, 1:] * rest[tri[:, 2]])
            a = surface_color(p_local, self.scene.triangle_material[prim], self.scene.materials)
            albedo[hit] = a
            shaded[hit] = shade(a, ans["primitive_normals"].numpy()[hit])
        return Hits(z, albedo, shaded)


def to_rgb8(rgb: np.ndarray, *, noise_dn: float, rng: np.random.Generator) -> np.ndarray:
    """Float RGB in [0, 1] to uint8 with Gaussian sensor noise of ``noise_dn`` grey levels."""
    img = rgb * 255.0
    if noise_dn > 0:
        img = img + rng.standard_normal(img.shape, dtype=np.float32) * np.float32(noise_dn)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


__all__ = ["BACKGROUND_RGB", "CameraRays", "Hits", "Renderer", "camera_rays", "luminance", "to_rgb8"]
