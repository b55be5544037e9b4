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


PRIMES = (np.uint64(0x8DA6B343), np.uint64(0xD8163841), np.uint64(0xCB1AB31F), np.uint64(0x9E3779B1),
           np.uint64(0x85EBCA77))


def _hash(*keys: np.ndarray) -> np.ndarray:
    """A 64-bit integer hash of up to five integer arrays (splitmix64 finaliser); wraps by design."""
    with np.errstate(over="ignore"):
        h = np.uint64(0)
        for k, prime in zip(keys, PRIMES):
            h = h ^ (np.asarray(k).astype(np.int64).astype(np.uint64) * prime)
        h = (h ^ (h >> np.uint64(30))) * _M2
        h = (h ^ (h >> np.uint64(27))) * _M3
        return h ^ (h >> np.uint64(31))


# Cell grids are offset by irrational fractions so that flat faces (z = 0 of a quad, the
# faces of a box) never lie on a cell boundary, where rounding would make the colour flicker.
OFFSET = np.array([0.3183099, 0.2718282, 0.1414214], dtype=np.float32)


def _cell_hash(p: np.ndarray, size, material: np.ndarray, salt: int) -> np.ndarray:
    """Hash of the cell of side ``size`` (m; scalar or ``(N, 1)``) holding each point."""
    c = np.floor(p / size + OFFSET * np.float32(salt)).astype(np.int64)
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
    table = _material_table(materials or {}, int(mat.max(initial=0)) + 1)
    spec = {k: v[mat][:, None] for k, v in table.items()}
    fine = _rgb(_cell_hash(p, spec["fine_m"], mat, 1))
    grain = _unit(_cell_hash(p, spec["fine_m"] * np.float32(0.25), mat, 4), 48)[:, None] - np.float32(0.5)
    coarse = _rgb(_cell_hash(p, spec["coarse_m"], mat, 2))
    tint = _rgb(_hash(np.arange(len(table["brightness"])), np.int64(7)))[mat]
    color = (np.float32(0.45) * fine + np.float32(0.35) * coarse + np.float32(0.2) * tint
             + np.float32(0.25) * grain) * spec["brightness"]
    patch = _unit(_cell_hash(p, spec["patch_m"], mat, 3), 40)[:, None]
    dark = patch < spec["dark_fraction"]
    flat = (patch >= spec["dark_fraction"]) & (patch < spec["dark_fraction"] + spec["flat_fraction"])
    color = np.where(dark, np.float32(0.03), color)
    color = np.where(flat, np.float32(0.55) * tint + np.float32(0.2), color)
    return np.clip(color, 0.0, 1.0)


def _material_table(materials: dict[int, Material], n: int) -> dict[str, np.ndarray]:
    """Material parameters as arrays indexed by material id (defaults where not given)."""
    specs = [materials.get(i, Material()) for i in range(max(n, max(materials, default=0) + 1))]
    return {f: np.array([getattr(s, f) for s in specs], dtype=np.float32)
            for f in ("fine_m", "coarse_m", "patch_m", "dark_fraction", "flat_fraction", "brightness")}


LUMA = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
LIGHT_DIR = np.array([0.3, -0.5, 0.8], dtype=np.float32) / np.float32(np.linalg.norm([0.3, -0.5, 0.8]))
AMBIENT = np.float32(0.45)


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of RGB in [0, 1], shape ``(..., 3)`` -> ``(...)``."""
    return rgb[..., 0] * LUMA[0] + rgb[..., 1] * LUMA[1] + rgb[..., 2] * LUMA[2]


def shade(albedo: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Lambertian shading (view independent) of ``(N, 3)`` albedo with world normals ``(N, 3)``:
    ``albedo * (AMBIENT + (1 - AMBIENT) |n . LIGHT_DIR|)``."""
    lam = np.abs(normals @ LIGHT_DIR)
    return albedo * (AMBIENT + (np.float32(1) - AMBIENT) * lam)[:, None]


def material_arrays(materials: dict[int, Material]) -> tuple[np.ndarray, np.ndarray]:
    """``(M, 6)`` float32 parameters (fine_m, coarse_m, patch_m, dark_fraction, flat_fraction,
    brightness) and ``(M, 3)`` float32 tint per material id, for the compiled kernel."""
    table = _material_table(materials, 1)
    params = np.stack([table[f] for f in ("fine_m", "coarse_m", "patch_m", "dark_fraction", "flat_fraction",
                                          "brightness")], axis=1)
    tint = _rgb(_hash(np.arange(len(params)), np.int64(7)))
    return params.astype(np.float32), tint.astype(np.float32)
