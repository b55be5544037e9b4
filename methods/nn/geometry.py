"""Depth-image geometry in torch: back-projection and normals from four neighbours.

Conventions (those of :class:`capture.camera.Intrinsics`): pixel ``(u, v)`` has its centre at
integer coordinates, a depth camera point is ``((u - cx) z / fx, (v - cy) z / fy, z)`` in metres,
``x`` right, ``y`` down, ``z`` forward. Shapes are NCHW: depth ``(B, 1, H, W)`` metres, points
and normals ``(B, 3, H, W)``, intrinsics ``(B, 4)`` as ``fx, fy, cx, cy`` (pixels), or ``(1, 4)`` / ``(4,)`` for the whole batch.

Normals use the four direct neighbours (DDRNet's depth-to-normal layer, seed III-A): the
tangents are the central differences ``P(u+1) - P(u-1)`` and ``P(v+1) - P(v-1)``, the normal is
their cross product, normalised and oriented towards the camera (``n_z < 0``). A normal is valid
where the pixel and its four neighbours are valid (image borders are invalid).
"""
from __future__ import annotations

import torch
import torch.nn.functional as F


def _intrinsics(K: torch.Tensor, batch: int, like: torch.Tensor) -> torch.Tensor:
    K = torch.as_tensor(K, dtype=like.dtype, device=like.device)
    if K.ndim == 1 or K.shape[0] == 1:
        K = K.reshape(1, 4).expand(batch, 4)
    return K.reshape(batch, 4, 1, 1)


def pixel_grid(height: int, width: int, *, like: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(u, v)`` pixel-centre coordinates, each ``(1, 1, H, W)``."""
    v, u = torch.meshgrid(torch.arange(height, dtype=like.dtype, device=like.device),
                          torch.arange(width, dtype=like.dtype, device=like.device), indexing="ij")
    return u[None, None], v[None, None]


def backproject(depth: torch.Tensor, K: torch.Tensor) -> torch.Tensor:
    """Depth ``(B, 1, H, W)`` metres -> camera points ``(B, 3, H, W)`` metres (holes stay as given)."""
    b, _, h, w = depth.shape
    k = _intrinsics(K, b, depth)
    u, v = pixel_grid(h, w, like=depth)
    x = (u - k[:, 2:3]) / k[:, 0:1] * depth
    y = (v - k[:, 3:4]) / k[:, 1:2] * depth
    return torch.cat([x, y, depth], dim=1)


def normals_from_points(points: torch.Tensor, valid: torch.Tensor | None = None,
                        *, eps: float = 1e-12) -> tuple[torch.Tensor, torch.Tensor]:
    """Unit normals ``(B, 3, H, W)`` from four neighbours and their validity ``(B, 1, H, W)`` bool.

    ``valid`` (``(B, 1, H, W)`` bool) marks pixels with a depth; ``None``: all finite points.
    Invalid normals are zero.
    """
    if valid is None:
        valid = torch.isfinite(points).all(dim=1, keepdim=True)
    p = torch.where(valid, points, torch.zeros_like(points))
    pp = F.pad(p, (1, 1, 1, 1))
    vp = F.pad(valid.to(points.dtype), (1, 1, 1, 1))
    du = pp[:, :, 1:-1, 2:] - pp[:, :, 1:-1, :-2]
    dv = pp[:, :, 2:, 1:-1] - pp[:, :, :-2, 1:-1]
    ok = valid & (vp[:, :, 1:-1, 2:] > 0) & (vp[:, :, 1:-1, :-2] > 0) & (vp[:, :, 2:, 1:-1] > 0) & (vp[:, :, :-2, 1:-1] > 0)
    n = torch.cross(dv, du, dim=1)  # x right, y down: dv x du points towards the camera (-z) on a fronto-parallel plane
    norm = torch.sqrt((n * n).sum(dim=1, keepdim=True) + eps)
    n = n / norm
    ok = ok & (norm > 1e-9)
    return torch.where(ok, n, torch.zeros_like(n)), ok


def normals_from_depth(depth: torch.Tensor, K: torch.Tensor,
                       valid: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`normals_from_points` of :func:`backproject`; ``valid`` default: finite, positive depth."""
    if valid is None:
        valid = torch.isfinite(depth) & (depth > 0)
    d = torch.where(valid, depth, torch.zeros_like(depth))
    return normals_from_points(backproject(d, K), valid)
