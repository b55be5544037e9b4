"""Compiled, hole-aware weighted-mean kernels shared by the classical filters.

Every classical filter of section II of the seed report is one weighted mean over a window:

    out(p) = sum_q w(p, q) I(q) / sum_q w(p, q),      q in N(p), I(q) valid       (eq. 5-6, 10, 11)
    w(p, q) = exp(-|p - q|^2 / (2 sigma_s^2) - c(p) |G(p) - G(q)|^2),  c(p) = 1 / (2 sigma_r(p)^2)

with ``G`` the range guide (the depth itself for the bilateral filter, the colour image for the
joint bilateral filter, the previous iterate ``J^t`` for the rolling guidance filter) and ``c = 0``
for the plain Gaussian (eq. 10). Holes (``NaN`` in ``I``) and pixels outside the image take no part
in any sum: they are left out of ``N(p)``, they are not weighted by zero-valued depth.

The window ``N(p)`` is the disk ``dx^2 + dy^2 <= radius^2`` (the same pixel set as OpenCV's
``bilateralFilter`` / ``jointBilateralFilter`` with ``d = 2 * radius + 1``).

Implementation (numba, ``parallel=True``, ``fastmath=False``):

* one image row per task; for each window offset the inner loop runs along the row over contiguous
  memory, so LLVM vectorises it (AVX2 / AVX-512 where present);
* ``exp`` is evaluated by :func:`_exp_neg`, a Cody-Waite range reduction plus the Cephes ``expf``
  polynomial and an exponent built from bits. Its relative error is below 1e-7 (under one float32
  ulp) on ``[0, 87]`` and, unlike a library call, it vectorises. Weights whose exponent exceeds
  :data:`T_MAX` (``exp(-40) = 4e-18`` of the centre weight) are dropped;
* a hole is a ``NaN`` in the neighbour guide: its exponent is ``NaN``, the ``t < T_MAX`` test fails
  and its weight is exactly zero, with no branch in the loop;
* sums are taken in float32 of ``I(q) - ref(p)`` with ``ref(p)`` close to the result (the centre
  value), which keeps the float32 sums accurate to a few ulp of the depth.
"""
from __future__ import annotations

import math
import os

import numba
import numpy as np
from llvmlite import ir
from numba import njit, prange, types
from numba.extending import intrinsic

from methods.errors import MethodError

# OpenMP first: probing TBB first prints a warning where an old libtbb is on the path (open3d ships one)
if "NUMBA_THREADING_LAYER" not in os.environ and "NUMBA_THREADING_LAYER_PRIORITY" not in os.environ:
    numba.config.THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]

#: exponents above this are treated as weight 0 (exp(-40) = 4.2e-18)
T_MAX = 40.0

_LOG2E = np.float32(1.4426950408889634)
_LN2_HI = np.float32(0.693359375)          # exactly representable: n * _LN2_HI is exact
_LN2_LO = np.float32(-2.12194440e-4)
_P0 = np.float32(1.9875691500e-4)
_P1 = np.float32(1.3981999507e-3)
_P2 = np.float32(8.3334519073e-3)
_P3 = np.float32(4.1665795894e-2)
_P4 = np.float32(1.6666665459e-1)
_P5 = np.float32(5.0000001201e-1)
_HALF = np.float32(0.5)
_ONE = np.float32(1.0)
_ZERO = np.float32(0.0)
_TMAX32 = np.float32(T_MAX)


@intrinsic
def _bits_as_float32(typingctx, v):
    """Reinterpret the low 32 bits of an integer as a float32 (an LLVM bitcast)."""
    if not isinstance(v, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        x = args[0]
        if v.bitwidth != 32:
            x = builder.trunc(x, ir.IntType(32))
        return builder.bitcast(x, ir.FloatType())

    return types.float32(v), codegen


@njit(inline="always", cache=True)
def _exp_neg(t):
    """``exp(-t)`` in float32 for ``0 <= t <= 87`` (relative error < 1e-7)."""
    n = np.int32(t * _LOG2E + _HALF)          # t >= 0: truncation of t/ln2 + 0.5 rounds
    fn = np.float32(n)
    r = (fn * _LN2_HI - t) + fn * _LN2_LO      # r = n ln2 - t in [-ln2/2, ln2/2]
    p = ((((_P0 * r + _P1) * r + _P2) * r + _P3) * r + _P4) * r + _P5
    e = (p * r * r + r) + _ONE                 # exp(r)
    return e * _bits_as_float32((np.int32(127) - n) << np.int32(23))   # * 2^-n


@njit(cache=True)
def exp_neg(t):
    """Vector form of :func:`_exp_neg` (for tests): ``exp(-t)`` of a float32 array."""
    out = np.empty_like(t)
    for i in range(t.size):
        out.flat[i] = _exp_neg(t.flat[i])
    return out


@njit(parallel=True, cache=True)
def _joint_mean_1(gc, gn, vn, ref, coef, oy, ox, st, r, out):
    """Single-channel guide. ``gc``, ``ref``, ``coef``, ``out``: (H, W); ``gn``, ``vn``: (H+2r, W+2r)."""
    H, W = gc.shape
    K = oy.size
    for y in prange(H):
        num = np.zeros(W, np.float32)
        den = np.zeros(W, np.float32)
        gcr = gc[y]
        refr = ref[y]
        cr = coef[y]
        for k in range(K):
            yy = y + r + oy[k]
            x0 = r + ox[k]
            s = st[k]
            gnr = gn[yy, x0:x0 + W]
            vnr = vn[yy, x0:x0 + W]
            for x in range(W):
                d = gcr[x] - gnr[x]
                t = s + cr[x] * (d * d)
                ok = t < _TMAX32                    # False for NaN: holes and the outside
                w = _exp_neg(t if ok else _TMAX32)
                w = w if ok else _ZERO
                num[x] += w * (vnr[x] - refr[x])
                den[x] += w
        for x in range(W):
            out[y, x] = refr[x] + num[x] / den[x] if den[x] > _ZERO else np.float32(np.nan)


@njit(parallel=True, cache=True)
def _joint_mean_3(gc, gn, vn, ref, coef, oy, ox, st, r, out):
    """Three-channel guide, planar: ``gc`` (3, H, W), ``gn`` (3, H+2r, W+2r); the rest as above."""
    H, W = ref.shape
    K = oy.size
    for y in prange(H):
        num = np.zeros(W, np.float32)
        den = np.zeros(W, np.float32)
        g0 = gc[0, y]
        g1 = gc[1, y]
        g2 = gc[2, y]
        refr = ref[y]
        cr = coef[y]
        for k in range(K):
            yy = y + r + oy[k]
            x0 = r + ox[k]
            s = st[k]
            n0 = gn[0, yy, x0:x0 + W]
            n1 = gn[1, yy, x0:x0 + W]
            n2 = gn[2, yy, x0:x0 + W]
            vnr = vn[yy, x0:x0 + W]
            for x in range(W):
                d0 = g0[x] - n0[x]
                d1 = g1[x] - n1[x]
                d2 = g2[x] - n2[x]
                t = s + cr[x] * ((d0 * d0 + d1 * d1) + d2 * d2)
                ok = t < _TMAX32
                w = _exp_neg(t if ok else _TMAX32)
                w = w if ok else _ZERO
                num[x] += w * (vnr[x] - refr[x])
                den[x] += w
        for x in range(W):
            out[y, x] = refr[x] + num[x] / den[x] if den[x] > _ZERO else np.float32(np.nan)


@njit(parallel=True, cache=True)
def _gaussian_mean(vn, mn, ref, oy, ox, sw, r, out):
    """Normalised Gaussian over valid pixels: ``vn`` values (0 at holes), ``mn`` 1/0 validity."""
    H, W = ref.shape
    K = oy.size
    for y in prange(H):
        num = np.zeros(W, np.float32)
        den = np.zeros(W, np.float32)
        refr = ref[y]
        for k in range(K):
            yy = y + r + oy[k]
            x0 = r + ox[k]
            w = sw[k]
            vnr = vn[yy, x0:x0 + W]
            mnr = mn[yy, x0:x0 + W]
            for x in range(W):
                m = w * mnr[x]
                num[x] += m * (vnr[x] - refr[x])
                den[x] += m
        for x in range(W):
            out[y, x] = refr[x] + num[x] / den[x] if den[x] > _ZERO else np.float32(np.nan)


# ----------------------------------------------------------------------------- python side
def disk_window(radius: int, sigma_spatial: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Offsets ``(dy, dx)`` of the disk ``dy^2 + dx^2 <= radius^2`` and their spatial exponents.

    Returns ``(dy, dx, s)`` with ``s = (dy^2 + dx^2) / (2 sigma_spatial^2)`` (float32): the closeness
    ``c(xi, x) = exp(-s)`` of eq. 7.
    """
    dy, dx = np.mgrid[-radius:radius + 1, -radius:radius + 1]
    inside = dy ** 2 + dx ** 2 <= radius * radius
    dy = dy[inside].astype(np.int64)
    dx = dx[inside].astype(np.int64)
    s = ((dy ** 2 + dx ** 2) / (2.0 * float(sigma_spatial) ** 2)).astype(np.float32)
    return dy, dx, s


def _padded(a: np.ndarray, r: int, fill: float) -> np.ndarray:
    shape = a.shape[:-2] + (a.shape[-2] + 2 * r, a.shape[-1] + 2 * r)
    out = np.full(shape, fill, np.float32)
    out[..., r:r + a.shape[-2], r:r + a.shape[-1]] = a
    return out


def joint_mean(value: np.ndarray, guide: np.ndarray, coef: np.ndarray | float, *, sigma_spatial: float,
               radius: int, ref: np.ndarray | None = None, guide_center: np.ndarray | None = None) -> np.ndarray:
    """Hole-aware joint bilateral weighted mean (the kernel of eq. 5-8 and eq. 11).

    Args:
        value: ``(H, W)`` float32, NaN holes: the image averaged (``f`` in eq. 5, ``I`` in eq. 11).
        guide: ``(H, W)`` or ``(C, H, W)`` with C = 3, float32: the range guide at the neighbours.
        coef: ``1 / (2 sigma_r^2)`` per pixel ``(H, W)`` or one number; 0 turns the range kernel off.
        sigma_spatial, radius: spatial Gaussian (pixels) and disk radius.
        ref: ``(H, W)`` finite offsets the sums are taken around (default: the value, or 0 at holes).
        guide_center: the guide at the window centres if it differs from ``guide`` (default ``guide``).

    Returns:
        ``(H, W)`` float32, NaN where no valid neighbour has a weight.
    """
    value = np.require(value, np.float32, ["C", "W"])
    H, W = value.shape
    valid = np.isfinite(value)
    r = int(radius)
    guide = np.asarray(guide, np.float32)
    gc = np.require(guide if guide_center is None else guide_center, np.float32, ["C", "W"])
    gn = _padded(np.where(valid, guide, np.float32(np.nan)), r, np.nan)
    vn = _padded(np.where(valid, value, np.float32(0.0)), r, 0.0)
    if ref is None:
        ref = np.where(valid, value, np.float32(0.0))
    ref = np.where(np.isfinite(ref), ref, np.float32(0.0)).astype(np.float32, copy=False)
    coef = np.asarray(coef, np.float32)
    coef = np.full((H, W), coef, np.float32) if coef.ndim == 0 else np.require(coef, np.float32, ["C", "W"])
    dy, dx, s = disk_window(r, sigma_spatial)
    out = np.empty((H, W), np.float32)
    if guide.ndim == 2:
        _joint_mean_1(gc, gn, vn, ref, coef, dy, dx, s, r, out)
    elif guide.ndim == 3 and guide.shape[0] == 3:
        _joint_mean_3(gc, gn, vn, ref, coef, dy, dx, s, r, out)
    else:  # pragma: no cover - callers pass (H, W) or (3, H, W)
        raise MethodError(f"guide must be (H, W) or (3, H, W), got {guide.shape}")
    return out


def gaussian_mean(value: np.ndarray, *, sigma_spatial: float, radius: int) -> np.ndarray:
    """Hole-aware normalised Gaussian (eq. 10 with N(p) restricted to valid pixels).

    ``(H, W)`` float32 NaN holes in, ``(H, W)`` float32 out; NaN where the disk holds no valid pixel.
    """
    value = np.asarray(value, np.float32)
    valid = np.isfinite(value)
    r = int(radius)
    vn = _padded(np.where(valid, value, np.float32(0.0)), r, 0.0)
    mn = _padded(valid.astype(np.float32), r, 0.0)
    ref = np.where(valid, value, np.float32(0.0))
    dy, dx, s = disk_window(r, sigma_spatial)
    sw = np.exp(-s.astype(np.float64)).astype(np.float32)
    out = np.empty(value.shape, np.float32)
    _gaussian_mean(vn, mn, ref, dy, dx, sw, r, out)
    return out


def default_radius(sigma_spatial: float) -> int:
    """The documented default window: ``radius = max(1, ceil(2 * sigma_spatial))``."""
    return max(1, int(math.ceil(2.0 * float(sigma_spatial) - 1e-9)))
