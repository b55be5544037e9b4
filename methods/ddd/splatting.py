"""Differentiable forward splatting between calibrated views (seed eq. 21, Fig. 8).

A source pixel ``p_s`` with depth ``D_s(p_s)`` moves to the target image at

    T_{s->t}(p_s) = pi(T_ts pi^-1(D_s(p_s), K_s), K_t)                               (eq. 21)

(``pi``: pinhole projection, ``pi^-1``: back-projection; no lens distortion, the suite's simulated
rigs and registered depth have none). Its values (colour, depth) are spread bilinearly over the
four target pixels around that sub-pixel position, each contribution weighted by the bilinear
weight times the source pixel's confidence ``w = exp(-2 z_t / z_max)`` (``z_t`` its depth in the
target camera; the released code's depth-dependent weight, so nearer surfaces dominate where
several land on one pixel), accumulated over all source pixels (and all source views), then
normalised by the accumulated weight. Gradients reach the source depth through the projected
position (bilinear weights) and through ``w``.

Shapes: depth ``(B, 1, H, W)`` metres, values ``(B, C, H, W)``, intrinsics ``(B, 4)`` ``fx, fy, cx,
cy``, transforms ``(B, 4, 4)`` ``T_target_source`` metres.
"""
from __future__ import annotations

import torch

from methods.nn.geometry import backproject


def project_to(depth: torch.Tensor, K_s: torch.Tensor, T_ts: torch.Tensor,
               K_t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Eq. 21: target pixel coordinates ``(B, 2, H, W)`` (u, v) and target depth ``(B, 1, H, W)``."""
    b, _, h, w = depth.shape
    p = backproject(depth, K_s).flatten(2)  # (B, 3, N)
    q = T_ts[:, :3, :3] @ p + T_ts[:, :3, 3:4]
    z = q[:, 2:3]
    zs = torch.where(z.abs() > 1e-6, z, torch.full_like(z, 1e-6))
    kt = K_t.reshape(b, 4, 1)
    u = kt[:, 0:1] * q[:, 0:1] / zs + kt[:, 2:3]
    v = kt[:, 1:2] * q[:, 1:2] / zs + kt[:, 3:4]
    return torch.cat([u, v], 1).reshape(b, 2, h, w), z.reshape(b, 1, h, w)


def splat(values: torch.Tensor, uv: torch.Tensor, weight: torch.Tensor, size: tuple[int, int]) -> tuple[torch.Tensor, torch.Tensor]:
    """Bilinear forward splatting: ``(sum w b v, sum w b)`` on a ``size`` = ``(H_t, W_t)`` grid.

    ``values`` ``(B, C, H, W)``, ``uv`` ``(B, 2, H, W)`` target pixel coordinates, ``weight``
    ``(B, 1, H, W)`` (0 = not splatted). Returns ``(B, C, H_t, W_t)`` and ``(B, 1, H_t, W_t)``;
    contributions falling outside the target image are dropped.
    """
    b, c = values.shape[:2]
    ht, wt = size
    u, v = uv[:, 0:1], uv[:, 1:2]
    u0, v0 = torch.floor(u.detach()), torch.floor(v.detach())
    acc = values.new_zeros(b, c, ht * wt)
    wacc = values.new_zeros(b, 1, ht * wt)
    for du in (0, 1):
        for dv in (0, 1):
            ui, vi = u0 + du, v0 + dv
            bw = (1 - (u - ui).abs()) * (1 - (v - vi).abs()) * weight
            inside = (ui >= 0) & (ui <= wt - 1) & (vi >= 0) & (vi <= ht - 1) & (bw > 0)
            bw = torch.where(inside, bw, torch.zeros_like(bw)).flatten(2)
            idx = torch.where(inside, vi * wt + ui, torch.zeros_like(ui)).long().flatten(2)
            acc = acc.scatter_add(2, idx.expand(b, c, -1), values.flatten(2) * bw)
            wacc = wacc.scatter_add(2, idx, bw)
    return acc.reshape(b, c, ht, wt), wacc.reshape(b, 1, ht, wt)


def depth_weight(z: torch.Tensor, *, z_max: float) -> torch.Tensor:
    """The source confidence ``exp(-2 z / z_max)`` (0 for points behind the camera)."""
    return torch.where(z > 1e-6, torch.exp(-2.0 * z / z_max), torch.zeros_like(z))


def render_view(sources: list[dict], K_t: torch.Tensor, size: tuple[int, int], *, z_max: float,
                eps: float = 1e-8) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Splat every source view into the target and normalise.

    ``sources``: dicts with ``depth`` ``(B, 1, H, W)`` metres, ``valid`` ``(B, 1, H, W)`` bool,
    ``color`` ``(B, C, H, W)``, ``K`` ``(B, 4)``, ``T_ts`` ``(B, 4, 4)``. Returns the rendered
    colour ``(B, C, H_t, W_t)``, rendered depth ``(B, 1, H_t, W_t)`` (target-camera z) and the
    accumulated weight ``(B, 1, H_t, W_t)`` (0 where nothing landed).
    """
    acc_c = acc_z = acc_w = None
    for s in sources:
        uv, z = project_to(torch.where(s["valid"], s["depth"], torch.zeros_like(s["depth"])), s["K"], s["T_ts"], K_t)
        w = depth_weight(z, z_max=z_max) * s["valid"].to(z.dtype)
        c, ww = splat(torch.cat([s["color"], z], 1), uv, w, size)
        acc_c = c if acc_c is None else acc_c + c
        acc_w = ww if acc_w is None else acc_w + ww
    n = acc_c.shape[1] - 1
    norm = torch.where(acc_w > eps, acc_w, torch.ones_like(acc_w))
    out = acc_c / norm * (acc_w > eps).to(acc_c.dtype)
    return out[:, :n], out[:, n:], acc_w
