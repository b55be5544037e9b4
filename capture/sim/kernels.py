"""Compiled (numba) per-pixel kernel: hit -> texture, shading, luminance, 8-bit colour.

It does, pixel by pixel and in one pass, what :func:`capture.sim.texture.surface_color`,
:func:`capture.sim.texture.shade` and :func:`capture.sim.render.to_rgb8` do with numpy arrays
(those stay the readable reference; ``tests/capture/test_sim_render.py`` checks the two agree).
The colour noise is Irwin-Hall (sum of four uniform bytes of a hash of the pixel index and a
per-frame seed), close to Gaussian with standard deviation ``noise_dn``.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from capture.sim.texture import AMBIENT, LIGHT_DIR, LUMA, OFFSET, PRIMES, _M2, _M3

_P = np.array([int(p) for p in PRIMES], dtype=np.uint64)
_IRWIN_HALL_STD = np.float32(np.sqrt(4 * (256 ** 2 - 1) / 12.0))


@njit(cache=True, nogil=True, inline="always")
def _mix(a, b, c, d, e):
    h = (np.uint64(a) * _P[0]) ^ (np.uint64(b) * _P[1]) ^ (np.uint64(c) * _P[2]) ^ (np.uint64(d) * _P[3]) \
        ^ (np.uint64(e) * _P[4])
    h = (h ^ (h >> np.uint64(30))) * np.uint64(_M2)
    h = (h ^ (h >> np.uint64(27))) * np.uint64(_M3)
    return h ^ (h >> np.uint64(31))


@njit(cache=True, nogil=True, inline="always")
def _cell(px, py, pz, size, m, salt):
    s = np.float32(salt)
    cx = np.int64(np.floor(px / size + OFFSET[0] * s))
    cy = np.int64(np.floor(py / size + OFFSET[1] * s))
    cz = np.int64(np.floor(pz / size + OFFSET[2] * s))
    return _mix(cx, cy, cz, np.int64(m), np.int64(salt))


@njit(cache=True, nogil=True, inline="always")
def _unit(h, shift):
    return np.float32((h >> np.uint64(shift)) & np.uint64(255)) / np.float32(255.0)


@njit(cache=True, nogil=True, inline="always")
def _channel(k, h_fine, h_coarse, grain, patch, tint_k, p):
    """Albedo of channel ``k`` (p = the material's parameter row)."""
    if patch < p[3]:
        return np.float32(0.03)
    if patch < p[3] + p[4]:
        x = np.float32(0.55) * tint_k + np.float32(0.2)
    else:
        sh = 8 * (k + 1)
        x = (np.float32(0.45) * _unit(h_fine, sh) + np.float32(0.35) * _unit(h_coarse, sh)
             + np.float32(0.2) * tint_k + np.float32(0.25) * grain) * p[5]
    return min(max(x, np.float32(0.0)), np.float32(1.0))


@njit(cache=True, nogil=True)
def shade_hits(t_hit, prim, uvs, normals, idx, triangles, rest, tri_mat, tri_part, params, tint, background,
               z_out, lum_albedo_out, lum_shaded_out, rgb_out, part_out):
    """For cast result ``j`` (arrays of length M from Open3D), fill pixel ``idx[j]`` of
    ``z_out`` (N,) float32 metres (NaN = no hit), ``lum_albedo_out``/``lum_shaded_out`` (N,)
    float32, ``rgb_out`` (N, 3) float32 shaded colour in [0, 1] and ``part_out`` (N,) int32, the
    scene part of the triangle hit (``tri_part``; -1 = no hit)."""
    one = np.float32(1.0)
    for j in range(t_hit.shape[0]):
        i = idx[j]
        t = t_hit[j]
        if not np.isfinite(t):
            z_out[i] = np.nan
            part_out[i] = -1
            lum_albedo_out[i] = background
            lum_shaded_out[i] = background
            rgb_out[i, 0] = rgb_out[i, 1] = rgb_out[i, 2] = background
            continue
        z_out[i] = t
        tri = prim[j]
        part_out[i] = tri_part[tri]
        u = uvs[j, 0]
        v = uvs[j, 1]
        w = one - u - v
        a, bb, c = triangles[tri, 0], triangles[tri, 1], triangles[tri, 2]
        px = w * rest[a, 0] + u * rest[bb, 0] + v * rest[c, 0]
        py = w * rest[a, 1] + u * rest[bb, 1] + v * rest[c, 1]
        pz = w * rest[a, 2] + u * rest[bb, 2] + v * rest[c, 2]
        m = tri_mat[tri]
        p = params[m]
        h_fine = _cell(px, py, pz, p[0], m, 1)
        h_coarse = _cell(px, py, pz, p[1], m, 2)
        grain = _unit(_cell(px, py, pz, p[0] * np.float32(0.25), m, 4), 48) - np.float32(0.5)
        patch = _unit(_cell(px, py, pz, p[2], m, 3), 40)
        r = _channel(0, h_fine, h_coarse, grain, patch, tint[m, 0], p)
        g = _channel(1, h_fine, h_coarse, grain, patch, tint[m, 1], p)
        b = _channel(2, h_fine, h_coarse, grain, patch, tint[m, 2], p)
        lum_albedo_out[i] = r * LUMA[0] + g * LUMA[1] + b * LUMA[2]
        lam = abs(normals[j, 0] * LIGHT_DIR[0] + normals[j, 1] * LIGHT_DIR[1] + normals[j, 2] * LIGHT_DIR[2])
        f = AMBIENT + (one - AMBIENT) * lam
        r, g, b = r * f, g * f, b * f
        lum_shaded_out[i] = r * LUMA[0] + g * LUMA[1] + b * LUMA[2]
        rgb_out[i, 0] = r
        rgb_out[i, 1] = g
        rgb_out[i, 2] = b


@njit(cache=True, nogil=True)
def expose(rgb, noise_seed, noise_dn, out):
    """``rgb`` (N, 3) float32 in [0, 1] to ``out`` (N, 3) uint8 with Irwin-Hall sensor noise of
    standard deviation ``noise_dn`` grey levels, seeded by ``noise_seed`` and the pixel index."""
    seed_lo = np.int64(noise_seed & np.uint64(0xFFFFFFFF))
    seed_hi = np.int64(noise_seed >> np.uint64(32))
    scale = noise_dn / _IRWIN_HALL_STD
    for i in range(rgb.shape[0]):
        h2 = _mix(i, 1, seed_lo, seed_hi, 17)
        h1 = _mix(i, 2, seed_lo, seed_hi, 17)
        for k in range(3):
            h = h1 >> np.uint64(32 * (k % 2)) if k < 2 else h2
            s4 = np.float32((h & np.uint64(255)) + ((h >> np.uint64(8)) & np.uint64(255))
                            + ((h >> np.uint64(16)) & np.uint64(255)) + ((h >> np.uint64(24)) & np.uint64(255)))
            x = rgb[i, k] * np.float32(255.0) + (s4 - np.float32(510.0)) * scale
            out[i, k] = np.uint8(min(max(np.rint(x), np.float32(0.0)), np.float32(255.0)))


@njit(cache=True, nogil=True)
def depth_counts(depth, unit):
    """Float metres ``(H, W)`` (NaN = none) to uint16 counts of ``unit`` metres (0 = none or out
    of range); the same numbers as :func:`capture.session.encode_depth`, without temporaries."""
    out = np.empty(depth.shape, dtype=np.uint16)
    flat_in = depth.ravel()
    flat_out = out.ravel()
    for i in range(flat_in.size):
        c = np.rint(np.float64(flat_in[i]) / unit)
        flat_out[i] = np.uint16(c) if (c >= 1.0 and c <= 65535.0) else np.uint16(0)
    return out


@njit(cache=True, nogil=True)
def footprint_reduce(footprint, amplitude_weighted, z_out, near_out, far_out):
    """Per pixel of ``footprint`` ``(H, W, S)`` float32 metres (NaN = the ray met nothing): the mean of the finite
    depths (weighted by ``1 / z**2`` with ``amplitude_weighted``), the nearest and the farthest, into the ``(H, W)``
    float32 outputs (NaN where none is finite): :func:`capture.sim.noise.footprint_depth`
    (``tests/capture/test_sim_footprint.py`` checks it against a direct loop)."""
    H, W, S = footprint.shape
    for i in range(H):
        for j in range(W):
            num = 0.0
            den = 0.0
            lo = np.inf
            hi = -np.inf
            for k in range(S):
                z = footprint[i, j, k]
                if not np.isfinite(z):
                    continue
                w = 1.0 / (z * z) if amplitude_weighted else 1.0
                num += w * z
                den += w
                lo = min(lo, z)
                hi = max(hi, z)
            if den > 0:
                z_out[i, j] = num / den
                near_out[i, j] = lo
                far_out[i, j] = hi
            else:
                z_out[i, j] = near_out[i, j] = far_out[i, j] = np.nan
