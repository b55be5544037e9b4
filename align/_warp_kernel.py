"""The compiled point loop of :mod:`align.warp_numba` (imported only when that engine runs: numba
takes a while to import). Every helper keeps the numpy engine's float32 arithmetic order."""
from __future__ import annotations

import numba
import numpy as np

njit = numba.njit(cache=True, nogil=True, inline="always")  # helpers: inlined into the loop
f32 = np.float32


@njit
def diff_sum(p, k, step, c_minus, c_plus, N):
    """Sum of the differences to the continuous neighbours along one axis (``step`` = 1 or W)."""
    gl = f32(f32(p[k] - p[k - step]) * c_minus) if k >= step else f32(0)
    gr = f32(f32(p[k + step] - p[k]) * c_plus) if k + step < N else f32(0)
    return f32(gl + gr)


@njit
def store(buf, idx, val, prio, tmp, tmp_i):
    """Z-test one splat: the key (top bits of w, priority, w) wins when larger."""
    tmp[0] = val
    bits = np.int64(tmp_i[0])
    key = (((bits >> 18) << 8 | prio) << 32) | bits
    if key > buf[idx]:
        buf[idx] = key


@njit
def diagonal_cuts(cxp, cyp, k, W, links):
    """The quadrants cut at the diagonal, bits as :func:`align.warp_splat.diagonal_cuts`."""
    cl, cr, cu, cd = links
    q = 0
    if cr > 0 and cd > 0 and not (cyp[k + 1 + W] > 0 or cxp[k + W + 1] > 0):
        q |= 1
    if cl > 0 and cd > 0 and not (cyp[k - 1 + W] > 0 or cxp[k + W] > 0):
        q |= 2
    if cr > 0 and cu > 0 and not (cyp[k + 1] > 0 or cxp[k - W + 1] > 0):
        q |= 4
    if cl > 0 and cu > 0 and not (cyp[k - 1] > 0 or cxp[k - W] > 0):
        q |= 8
    return q


@njit
def edge_value(a, b, frac, jac, lims, grads, wk, cuts, dlim):
    """An edge point's splat at offset (a, b): its inverse depth, or -1 when the target lies
    beyond the point's reach (one grid step towards a continuous neighbour, the edge reach towards
    a discontinuous one, where the depth is held along that axis); and whether it lies past
    ``|sx| + |sy| < dlim`` in a quadrant cut at the diagonal (it then fills nothing on its own)."""
    jxu, jxv, jyu, jyv = jac
    lxp, lxm, lyp, lym = lims
    cu_ = f32(f32(a) - frac[0])
    cv_ = f32(f32(b) - frac[1])
    sx = f32(f32(jxu * cu_) + f32(jxv * cv_))
    sy = f32(f32(jyu * cu_) + f32(jyv * cv_))
    if not (sx < lxp and sx > lxm and sy < lyp and sy > lym):
        return f32(-1), False
    cut = False
    if cuts != 0:
        bit = (0 if sx > 0 else 1) + (0 if sy > 0 else 2)
        cut = (cuts >> bit) & 1 and f32(abs(sx) + abs(sy)) >= dlim
    kx = not ((sx > 0 and lxp < 1) or (sx < 0 and lxm > -1))
    ky = not ((sy > 0 and lyp < 1) or (sy < 0 and lym > -1))
    val = f32(grads[0] * f32(sx * f32(kx)))
    val = f32(val + f32(grads[1] * f32(sy * f32(ky))))
    val = f32(val + wk)
    if val < f32(1e-12):
        val = f32(1e-12)
    return val, cut


@njit
def edge_setup(links, sums, idet, reach):
    """Per edge point: the source-grid Jacobian (undoing the sums' factors), the reach limits
    along each axis (one step towards a continuous neighbour, ``reach`` of a step towards a
    discontinuous one), and the per-axis w gradient."""
    cl, cr, cu, cd = links
    ux, vx, wx, uy, vy, wy = sums
    nx = f32(cl + cr)
    ny = f32(cu + cd)
    e_idet = f32(idet * f32(nx * ny))
    jac = (f32(f32(vy * e_idet) / ny), f32(f32(-uy * e_idet) / ny),
           f32(f32(-vx * e_idet) / nx), f32(f32(ux * e_idet) / nx))
    hold = f32(1) - reach
    lims = (reach + hold * cr, -reach - hold * cl, reach + hold * cd, -reach - hold * cu)
    return jac, lims, (f32(wx / nx), f32(wy / ny))


@njit
def splat_edge(buf, cbuf, base, frac, links, sums, idet, wk, offs, Wp, tmp, tmp_i, reach, cuts):
    """An edge point's splats: within reach of the point (see :func:`edge_value`)."""
    A, B, P = offs
    jac, lims, grads = edge_setup(links, sums, idet, reach)
    dlim = f32(f32(1) + reach)
    for t in range(A.size):
        val, cut = edge_value(A[t], B[t], frac, jac, lims, grads, wk, cuts, dlim)
        if val >= f32(0):
            store(cbuf if cut else buf, base + B[t] * Wp + A[t], val, P[t], tmp, tmp_i)


@numba.njit(cache=True, nogil=True)
def kernel(buf, cbuf, u, v, w, cxp, cyp, valid, geom, offs):
    """Steps 3-5 for every point (see :mod:`align.warp_numba`). The fast path (interior points,
    the whole block on the local plane) stays in the loop: moved into a helper function it runs
    4x slower (measured), where the rarer edge path costs nothing as a call."""
    W, Wd, Hd, m, reach_scale, Wp, r, edge_reach = geom
    A, B, P = offs
    N = u.size
    tmp = np.empty(1, np.float32)
    tmp_i = tmp.view(np.int32)
    for k in range(N):
        if not valid[k]:
            continue
        links = (cxp[k], cxp[k + 1], cyp[k], cyp[k + W])
        if f32(links[0] + links[1]) == 0 or f32(links[2] + links[3]) == 0:  # flying pixel, one-pixel sliver
            continue
        if not (u[k] > -m and u[k] < Wd + m and v[k] > -m and v[k] < Hd + m):
            continue
        cl, cr, cu, cd = links
        ux, vx, wx = diff_sum(u, k, 1, cl, cr, N), diff_sum(v, k, 1, cl, cr, N), diff_sum(w, k, 1, cl, cr, N)
        uy, vy, wy = diff_sum(u, k, W, cu, cd, N), diff_sum(v, k, W, cu, cd, N), diff_sum(w, k, W, cu, cd, N)
        det = f32(f32(ux * vy) - f32(uy * vx))
        adet = abs(det)
        if not adet > f32(1e-6):
            continue
        gu = f32(f32(wx * vy) - f32(wy * vx))
        gv = f32(f32(wy * ux) - f32(wx * uy))
        reach = max(f32(abs(vy) + abs(uy)), f32(abs(vx) + abs(ux))) * reach_scale
        fast = reach < adet and cl + cr + cu + cd == 4
        cuts = diagonal_cuts(cxp, cyp, k, W, links) if cl + cr + cu + cd >= 2 else 0
        fast = fast and cuts == 0
        fu = np.floor(u[k])
        fv = np.floor(v[k])
        fru = f32(u[k] - fu)
        frv = f32(v[k] - fv)
        base = np.int64(fv + r) * Wp + np.int64(fu + r)
        idet = f32(f32(1) / det)
        if not fast:
            splat_edge(buf, cbuf, base, (fru, frv), links, (ux, vx, wx, uy, vy, wy), idet, w[k], offs, Wp, tmp, tmp_i,
                       edge_reach, cuts)
            continue
        sgu = f32(gu * idet)
        sgv = f32(gv * idet)
        base_w = f32(f32(w[k] - f32(sgu * fru)) - f32(sgv * frv))
        for t in range(A.size):
            val = f32(f32(sgu * f32(A[t])) + base_w)
            if B[t] != 0:
                val = f32(val + f32(sgv * f32(B[t])))
            store(buf, base + B[t] * Wp + A[t], val, P[t], tmp, tmp_i)

