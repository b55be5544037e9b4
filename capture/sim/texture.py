"""Procedural surface colour, fixed to each surface (pure numpy).

The colour of a surface point is a function of the point in its part's *local* frame and of
the part's material, so it moves with the part and is identical from every view (the shading
is Lambertian, which is view independent too). The pattern is a mosaic of randomly coloured
cells at two scales (many corners for SIFT/ORB/AKAZE) over a smooth tint, with coarse
patches that are dark or flat grey: the low-texture areas where a stereo matcher fails.

Example:
    >>> p = np.array([[0.01, 0.02, 0.0], [0.51, 0.02, 0.0]], dtype=np.float32)
    >>> c = surface_color(p, np.array([3, 3]))
    >>> c.shape, c.dtype, bool((c >= 0).all() and (c <= 1).all())
    ((2, 3), dtype('float32'), True)
    >>> bool((surface_color(p, np.array([3, 3])) == c).all())  # deterministic
    True
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_M1 = np.uint64(0x9E3779B97F4A7C15)
_M2 = np.uint64(0xBF58476D1CE4E5B9)
_M3 = np.uint64(0x94D049BB133111EB)


@dataclass(frozen=True)
class Material:
    """How a part is patterned.

    ``fine_m``/``coarse_m``: mosaic cell sizes in metres; ``patch_m``: size of the cells that
    decide dark or flat patches; ``dark_fraction``/``flat_fraction``: share of those patches.
    """

    fine_m: float = 0.04
    coarse_m: float = 0.15
    patch_m: float = 0.6
    dark_fraction: float = 0.08
    flat_fraction: float = 0.08
    brightness: float = 1.0


def _hash(*keys: np.ndarray) -> np.ndarray:
    """A 64-bit integer hash of integer arrays (splitmix64 finaliser); wraps by design."""
    h = np.zeros(np.broadcast(*keys).shape, dtype=np.uint64)
    with np.errstate(over="ignore"):
        for k in keys:
            h = (h ^ np.asarray(k).astype(np.int64).astype(np.uint64)) * _M1
            h ^= h >> np.uint64(30)
            h *= _M2
            h ^= h >> np.uint64(27)
            h *= _M3
            h ^= h >> np.uint64(31)
    return h


# Cell grids are offset by irrational fractions so that flat faces (z = 0 of a quad, the
# faces of a box) never lie on a cell boundary, where rounding would make the colour flicker.
_OFFSET = np.array([0.3183099, 0.2718282, 0.1414214], dtype=np.float32)


def _cell_hash(p: np.ndarray, size: float, material: np.ndarray, salt: int) -> np.ndarray:
    c = np.floor(p / np.float32(size) + _OFFSET * np.float32(salt)).astype(np.int64)
    return _hash(c[:, 0], c[:, 1], c[:, 2], material, np.int64(salt))


def _unit(h: np.ndarray, shift: int) -> np.ndarray:
    """8 bits of a hash as a float in [0, 1]."""
    return ((h >> np.uint64(shift)) & np.uint64(255)).astype(np.float32) / 255.0


def _rgb(h: np.ndarray) -> np.ndarray:
    return np.stack([_unit(h, 8), _unit(h, 16), _unit(h, 24)], axis=1)


def surface_color(p_local: np.ndarray, material_id: np.ndarray, materials: dict[int, Material] | None = None
                  ) -> np.ndarray:
    """Albedo colour of surface points.

    Args:
        p_local: ``(N, 3)`` points in their part's local frame, metres.
        material_id: ``(N,)`` integer material of each point (seeds the pattern).
        materials: optional pattern parameters per material id (default :class:`Material`).
    Returns:
        ``(N, 3)`` float32 RGB albedo in [0, 1].
    """
    p = np.asarray(p_local, dtype=np.float32)
    mat = np.asarray(material_id, dtype=np.int64)
    out = np.empty((len(p), 3), dtype=np.float32)
    for m in np.unique(mat):
        sel = mat == m
        spec = (materials or {}).get(int(m), Material())
        out[sel] = _material_color(p[sel], int(m), spec)
    return out


def _material_color(p: np.ndarray, m: int, spec: Material) -> np.ndarray:
    mid = np.int64(m)
    fine = _rgb(_cell_hash(p, spec.fine_m, mid, 1))
    coarse = _rgb(_cell_hash(p, spec.coarse_m, mid, 2))
    tint = _rgb(_hash(mid, np.int64(7)).reshape(1))
    color = (0.45 * fine + 0.35 * coarse + 0.2 * tint) * spec.brightness
    patch = _unit(_cell_hash(p, spec.patch_m, mid, 3), 40)
    dark = patch < spec.dark_fraction
    flat = (patch >= spec.dark_fraction) & (patch < spec.dark_fraction + spec.flat_fraction)
    color[dark] = 0.03
    color[flat] = 0.55 * tint + 0.2
    return np.clip(color, 0.0, 1.0)


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of RGB in [0, 1], shape ``(..., 3)`` -> ``(...)``."""
    return rgb[..., 0] * 0.2126 + rgb[..., 1] * 0.7152 + rgb[..., 2] * 0.0722


def shade(albedo: np.ndarray, normals: np.ndarray, *, light_dir=(0.3, -0.5, 0.8), ambient: float = 0.45) -> np.ndarray:
    """Lambertian shading (view independent) of ``(N, 3)`` albedo with world normals ``(N, 3)``."""
    L = np.asarray(light_dir, dtype=np.float32)
    L = L / np.linalg.norm(L)
    lam = np.abs(normals @ L)
    return albedo * (ambient + (1.0 - ambient) * lam)[:, None]
