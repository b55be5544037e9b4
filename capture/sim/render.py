"""Batched ray casting of a scene with Open3D's ``RaycastingScene`` (one cast per image).

Depth convention: the ray of pixel ``(u, v)`` has direction ``(x, y, 1)`` in the camera frame
(``(x, y)`` the undistorted normalised coordinates of the pixel), so Open3D's ``t_hit`` *is*
the z-depth in metres.

Shading normals: facets' normals on flat parts (walls, furniture); on smooth parts (bodies,
balloons) the vertex normals interpolated across each triangle (Phong normals), so curved
surfaces show no facets in the colour or the shaded luminance.

Speed: the rigs never move, so what a camera sees of the still parts of a scene (room,
furniture) is cast and shaded once per camera (the *still layer*). Each frame then casts only
the pixels whose rays can meet a moving part: the union of the image rectangles of every
moving part's bounding box (computed in undistorted normalised coordinates, so it is
conservative under lens distortion too). Those rays are cast against the whole scene, so the
result is the same as casting every pixel (``tests/capture/test_sim_render.py`` checks it).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import open3d as o3d
from numba import njit

from capture.camera import Intrinsics, Transform
from capture.sim.kernels import expose, shade_hits
from capture.sim.scene import Scene
from capture.sim.texture import material_arrays, shade, surface_color

BACKGROUND_RGB = 0.08  # colour of rays that hit nothing

_BOX_CORNERS = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)])


@dataclass(frozen=True, eq=False)
class CameraRays:
    """Rays of one (static) camera: ``rays`` ``(H*W, 6)`` float32 world origin+direction in
    row-major pixel order, and the undistorted normalised image coordinates ``xy`` ``(H, W, 2)``."""

    intrinsics: Intrinsics
    T_world_cam: Transform
    rays: np.ndarray
    xy: np.ndarray


def camera_rays(K: Intrinsics, T_world_cam: Transform) -> CameraRays:
    """Rays through every pixel centre of ``K`` (lens distortion included) posed by ``T_world_cam``."""
    d_cam = K.ray_grid()  # (H, W, 3) with z = 1
    d_world = d_cam @ T_world_cam.R.T
    origin = np.broadcast_to(T_world_cam.t, d_world.shape)
    rays = np.concatenate([origin, d_world], axis=-1).astype(np.float32).reshape(-1, 6)
    return CameraRays(K, T_world_cam, rays, d_cam[..., :2].astype(np.float32))


def footprint_rays(K: Intrinsics, T_world_cam: Transform, n: int) -> CameraRays:
    """Rays over every pixel's footprint: ``n x n`` per pixel of ``K``, at the centres of the ``n x n`` cells the
    pixel splits into (the camera at ``n`` times the resolution, :meth:`Intrinsics.scaled`). Pixel ``(u, v)``'s rays
    are those of fine pixels ``(n u + i, n v + j)``, ``i, j < n``, at ``(u + (i + 0.5) / n - 0.5, ...)``;
    :func:`footprint_samples` regroups a cast of them per pixel.

    >>> K = Intrinsics(4, 3, 100.0, 100.0, 1.5, 1.0)
    >>> rays = footprint_rays(K, Transform.identity(), 2)
    >>> rays.intrinsics.shape, [round(float(x) * 100, 2) for x in rays.xy[0, 0]]  # pixel (0, 0)'s first ray
    ((6, 8), [-1.75, -1.25])
    """
    return camera_rays(K.scaled(K.width * n, K.height * n), T_world_cam)


def footprint_samples(z_fine: np.ndarray, n: int) -> np.ndarray:
    """A cast of :func:`footprint_rays` ``(n H, n W)`` regrouped per pixel: ``(H, W, n * n)``."""
    H, W = z_fine.shape[0] // n, z_fine.shape[1] // n
    return z_fine.reshape(H, n, W, n).transpose(0, 2, 1, 3).reshape(H, W, n * n)


@dataclass
class Hits:
    """What one camera sees, all ``(H, W)``: ``z`` float32 metres (NaN = nothing), the
    luminance of the surface albedo and of the shaded colour (float32, [0, 1]), the colour
    image ``rgb`` ``(H, W, 3)`` uint8 with sensor noise, and ``part`` int32, the scene part each
    ray met (:attr:`capture.sim.scene.Scene.triangle_part`; -1 = nothing)."""

    z: np.ndarray
    albedo_luminance: np.ndarray
    shaded_luminance: np.ndarray
    rgb: np.ndarray
    part: np.ndarray


@dataclass
class _Layer:
    """Per-pixel shading buffers of one camera, flat: z, luminances (N,), colour (N, 3), part (N,)."""

    z: np.ndarray
    lum_albedo: np.ndarray
    lum_shaded: np.ndarray
    rgb: np.ndarray
    part: np.ndarray
    cast_pixels: int = field(default=0)

    @classmethod
    def empty(cls, n: int) -> "_Layer":
        return cls(np.empty(n, np.float32), np.empty(n, np.float32), np.empty(n, np.float32),
                   np.empty((n, 3), np.float32), np.full(n, -1, np.int32))

    def copy(self) -> "_Layer":
        return _Layer(self.z.copy(), self.lum_albedo.copy(), self.lum_shaded.copy(), self.rgb.copy(), self.part.copy())


class Renderer:
    """Casts camera rays into a :class:`Scene` at a given scene time.

    ``nthreads``: Embree threads (0 = all cores). ``reuse_still=False`` casts every pixel every
    frame (the reference the fast path is tested against).
    """

    def __init__(self, scene: Scene, *, nthreads: int = 0, reuse_still: bool = True) -> None:
        self.scene = scene
        self.nthreads = nthreads
        self.reuse_still = reuse_still
        self._triangles = o3d.core.Tensor(scene.triangles)
        self._params, self._tint = material_arrays(scene.materials)
        self._time: float | None = None
        self._rc: o3d.t.geometry.RaycastingScene | None = None
        self._vertices: np.ndarray | None = None
        self._normals: np.ndarray | None = None
        self._still: dict[int, _Layer] = {}
        self.last_cast_pixels = 0
        #: Seconds spent in Embree (``raycast``) and in the shading kernels (``shade``),
        #: accumulated over the renderer's life (``perf_counter``: cheap, unlike process CPU clocks).
        self.stage_s = {"raycast": 0.0, "shade": 0.0}

    # -- Embree scenes
    def _build(self, vertices: np.ndarray, triangles: np.ndarray) -> o3d.t.geometry.RaycastingScene:
        rc = o3d.t.geometry.RaycastingScene(nthreads=self.nthreads)
        rc.add_triangles(o3d.core.Tensor(vertices), o3d.core.Tensor(triangles))
        return rc

    def _scene_at(self, t_s: float) -> o3d.t.geometry.RaycastingScene:
        if self._rc is None or self._time != t_s:
            self._vertices = self.scene.vertices_at(t_s)
            self._normals = self.scene.normals_at(t_s) if self.scene.has_smooth else None
            self._rc = o3d.t.geometry.RaycastingScene(nthreads=self.nthreads)
            self._rc.add_triangles(o3d.core.Tensor(self._vertices), self._triangles)
            self._time = t_s
        return self._rc

    def _cast_into(self, rc, rays: np.ndarray, idx: np.ndarray, layer: _Layer, normals: np.ndarray | None) -> None:
        t0 = time.perf_counter()
        ans = {k: v.numpy() for k, v in rc.cast_rays(o3d.core.Tensor(rays), nthreads=self.nthreads).items()}
        t1 = time.perf_counter()
        scene = self.scene
        shade_hits(ans["t_hit"], ans["primitive_ids"], ans["primitive_uvs"], self.hit_normals(ans, normals), idx,
                   scene.triangles, scene.rest_vertices, scene.triangle_material, scene.triangle_part, self._params,
                   self._tint, np.float32(BACKGROUND_RGB), layer.z, layer.lum_albedo, layer.lum_shaded, layer.rgb,
                   layer.part)
        self.stage_s["raycast"] += t1 - t0
        self.stage_s["shade"] += time.perf_counter() - t1

    def hit_normals(self, ans: dict[str, np.ndarray], vertex_normals: np.ndarray | None = None) -> np.ndarray:
        """World normals of the hits of a cast (``ans``: Open3D's answer, any shape): the facet's
        normal, or on smooth parts the vertex normals (``vertex_normals``, default: the scene at
        the last cast time) interpolated with the hit's barycentric coordinates."""
        n = ans["primitive_normals"]
        vn = self._normals if vertex_normals is None else vertex_normals
        if vn is None:
            return n
        shape = ans["t_hit"].shape
        out = np.empty(shape + (3,), np.float32)
        _interpolate_normals(ans["t_hit"].reshape(-1), ans["primitive_ids"].reshape(-1),
                             ans["primitive_uvs"].reshape(-1, 2), n.reshape(-1, 3), self.scene.triangles,
                             self.scene.triangle_smooth, vn, out.reshape(-1, 3))
        return out

    def _still_layer(self, cam: CameraRays) -> _Layer:
        key = id(cam)
        if key not in self._still:
            n = len(cam.rays)
            layer = _Layer.empty(n)
            s = self.scene
            rc = self._build(s.vertices_at(0.0)[: s.n_still_vertices], s.triangles[: s.n_still_triangles])
            self._cast_into(rc, cam.rays, np.arange(n, dtype=np.int64), layer,
                            s.normals_at(0.0) if s.has_smooth else None)
            self._still[key] = (cam, layer)  # keep cam alive so id() stays unique
        return self._still[key][1]

    # -- the image region moving parts can cover
    def roi_indices(self, cam: CameraRays, t_s: float) -> np.ndarray:
        """Flat indices of the pixels whose rays can meet a moving part at ``t_s`` (sorted)."""
        self._scene_at(t_s)
        bounds = self.scene.moving_part_bounds(self._vertices)
        K = cam.intrinsics
        mask = np.zeros(K.shape, dtype=bool)
        for rect in _pixel_rects(bounds, cam):
            if rect is None:
                return np.arange(K.width * K.height, dtype=np.int64)
            r0, r1, c0, c1 = rect
            mask[r0:r1, c0:c1] = True
        return np.flatnonzero(mask)

    def cast(self, cam: CameraRays, t_s: float, *, noise_seed: int = 0, noise_dn: float = 0.0) -> Hits:
        """Cast ``cam``'s rays at scene time ``t_s`` seconds; texture, shade and expose the hits."""
        K = cam.intrinsics
        n = K.width * K.height
        rc = self._scene_at(t_s)
        idx = self._recast_indices(cam, t_s)
        if idx is not None:
            layer = self._still_layer(cam).copy()
        else:
            layer, idx = _Layer.empty(n), np.arange(n, dtype=np.int64)
        if idx.size:
            self._cast_into(rc, cam.rays[idx], idx, layer, self._normals)
        self.last_cast_pixels = int(idx.size)
        rgb8 = np.empty((n, 3), np.uint8)
        t0 = time.perf_counter()
        expose(layer.rgb, np.uint64(noise_seed), np.float32(noise_dn), rgb8)
        self.stage_s["shade"] += time.perf_counter() - t0
        H, W = K.shape
        return Hits(layer.z.reshape(H, W), layer.lum_albedo.reshape(H, W), layer.lum_shaded.reshape(H, W),
                    rgb8.reshape(H, W, 3), layer.part.reshape(H, W))

    @property
    def _keeps_still(self) -> bool:
        """Whether casts start from a still layer (:meth:`_still_layer`) and recast only what can move."""
        return self.reuse_still and self.scene.n_still_triangles > 0

    def _recast_indices(self, cam: CameraRays, t_s: float) -> np.ndarray | None:
        """Flat indices of ``cam``'s pixels to cast again over its still layer at ``t_s`` (none in a scene where
        nothing moves); None where the renderer keeps no still layer and casts every pixel."""
        if not self._keeps_still:
            return None
        if self.scene.n_still_triangles == len(self.scene.triangles):
            return np.zeros(0, np.int64)
        return self.roi_indices(cam, t_s)

    def still_depth(self, cam: CameraRays) -> np.ndarray | None:
        """The z-depth ``(H, W)`` float32 metres of ``cam``'s still layer (what it sees of the parts that never
        move), or None where the renderer keeps no still layer."""
        return self._still_layer(cam).z.reshape(cam.intrinsics.shape) if self._keeps_still else None

    def cast_depth(self, cam: CameraRays, t_s: float, *, within: np.ndarray | None = None) -> np.ndarray:
        """The z-depth ``(H, W)`` float32 metres (NaN = nothing) of ``cam``'s rays at ``t_s``: :meth:`cast`'s
        ``z`` without the shading (the still layer is shaded once, as for :meth:`cast`). ``within``: ``(H, W)``
        bool, the pixels a moving part may reach (the caller's bound); the others keep the still layer's depth.
        None: every pixel the moving parts' bounding boxes cover, as :meth:`cast`."""
        K = cam.intrinsics
        rc = self._scene_at(t_s)
        idx = self._recast_indices(cam, t_s)
        if idx is not None:
            z = self._still_layer(cam).z.copy()
            if within is not None:
                idx = idx[np.asarray(within, bool).reshape(-1)[idx]]
        else:
            z, idx = np.empty(K.width * K.height, np.float32), np.arange(K.width * K.height, dtype=np.int64)
        if idx.size:
            t0 = time.perf_counter()
            t_hit = rc.cast_rays(o3d.core.Tensor(cam.rays[idx]), nthreads=self.nthreads)["t_hit"].numpy()
            z[idx] = np.where(np.isfinite(t_hit), t_hit, np.nan)
            self.stage_s["raycast"] += time.perf_counter() - t0
        return z.reshape(K.shape)

    def cast_raw(self, cam: CameraRays, t_s: float) -> dict[str, np.ndarray]:
        """Open3D's full answer for every ray of ``cam`` at ``t_s`` (arrays shaped ``(H, W, ...)``)."""
        ans = self._scene_at(t_s).cast_rays(o3d.core.Tensor(cam.rays), nthreads=self.nthreads)
        H, W = cam.intrinsics.shape
        return {k: v.numpy().reshape((H, W) + v.numpy().shape[1:]) for k, v in ans.items()}


@njit(cache=True, nogil=True)
def _interpolate_normals(t_hit, prim, uvs, facet, triangles, smooth, vn, out):
    """``out[j]``: the facet normal of hit ``j``, or on a smooth triangle the unit vertex normals
    ``vn`` interpolated with the hit's barycentric coordinates ``(1 - u - v, u, v)``."""
    for j in range(t_hit.shape[0]):
        if not np.isfinite(t_hit[j]) or not smooth[prim[j]]:
            out[j, 0], out[j, 1], out[j, 2] = facet[j, 0], facet[j, 1], facet[j, 2]
            continue
        a, b, c = triangles[prim[j], 0], triangles[prim[j], 1], triangles[prim[j], 2]
        u, v = uvs[j, 0], uvs[j, 1]
        w = 1.0 - u - v
        x = w * vn[a, 0] + u * vn[b, 0] + v * vn[c, 0]
        y = w * vn[a, 1] + u * vn[b, 1] + v * vn[c, 1]
        z = w * vn[a, 2] + u * vn[b, 2] + v * vn[c, 2]
        norm = max(np.sqrt(x * x + y * y + z * z), 1e-12)
        out[j, 0], out[j, 1], out[j, 2] = x / norm, y / norm, z / norm


def _pixel_rects(bounds: np.ndarray, cam: CameraRays):
    """Yield ``(row0, row1, col0, col1)`` (end exclusive) per part box, ``None`` for "every pixel"
    (a box straddling the camera plane); boxes wholly behind the camera are skipped."""
    K, T = cam.intrinsics, cam.T_world_cam
    corners = np.where(_BOX_CORNERS[None, :, :, None] == 0, bounds[:, None, 0, :, None],
                       bounds[:, None, 1, :, None])[..., 0]  # (P, 8, 3)
    pc = (corners - T.t) @ T.R  # world -> camera
    z = pc[..., 2]
    for p in range(len(bounds)):
        if (z[p] <= 0).all():
            continue
        if (z[p] < 1e-3).any():
            yield None
            return
        x, y = pc[p, :, 0] / z[p], pc[p, :, 1] / z[p]
        rect = _normalised_rect_to_pixels(K, x.min(), x.max(), y.min(), y.max())
        if rect is not None:
            yield rect


def _normalised_rect_to_pixels(K: Intrinsics, x0, x1, y0, y1):
    if K.has_distortion:  # the image of the rectangle is bounded by the image of its border
        s = np.linspace(0.0, 1.0, 17)
        xs = np.concatenate([x0 + (x1 - x0) * s, np.full(17, x1), x0 + (x1 - x0) * s, np.full(17, x0)])
        ys = np.concatenate([np.full(17, y0), y0 + (y1 - y0) * s, np.full(17, y1), y0 + (y1 - y0) * s])
        d = K.distort(np.stack([xs, ys], axis=1))
        u, v = K.fx * d[:, 0] + K.cx, K.fy * d[:, 1] + K.cy
        u0, u1, v0, v1, margin = u.min(), u.max(), v.min(), v.max(), 3
    else:
        u0, u1, v0, v1, margin = K.fx * x0 + K.cx, K.fx * x1 + K.cx, K.fy * y0 + K.cy, K.fy * y1 + K.cy, 1
    c0, c1 = max(0, int(np.floor(u0)) - margin), min(K.width, int(np.ceil(u1)) + margin + 1)
    r0, r1 = max(0, int(np.floor(v0)) - margin), min(K.height, int(np.ceil(v1)) + margin + 1)
    return (r0, r1, c0, c1) if c0 < c1 and r0 < r1 else None


def reference_colors(renderer: Renderer, ans: dict[str, np.ndarray]) -> np.ndarray:
    """The shaded colour of a cast (``cast_raw``'s answer) computed with the numpy reference
    (:mod:`capture.sim.texture`): ``(H, W, 3)`` float32 in [0, 1]; for tests of the kernel."""
    scene = renderer.scene
    hit = np.isfinite(ans["t_hit"])
    out = np.full(ans["t_hit"].shape + (3,), BACKGROUND_RGB, dtype=np.float32)
    prim, uv = ans["primitive_ids"][hit], ans["primitive_uvs"][hit]
    tri = scene.triangles[prim]
    rest = scene.rest_vertices
    p = (1 - uv[:, :1] - uv[:, 1:]) * rest[tri[:, 0]] + uv[:, :1] * rest[tri[:, 1]] + uv[:, 1:] * rest[tri[:, 2]]
    albedo = surface_color(p, scene.triangle_material[prim], scene.materials)
    out[hit] = shade(albedo, renderer.hit_normals(ans)[hit])
    return out
