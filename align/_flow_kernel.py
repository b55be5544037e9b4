"""The compiled passes of :mod:`align.motion_flow` (imported on first use: numba takes a while to import).

:func:`scene_shift` and :func:`scene_motion` are steps 1-2 and 3 of :class:`align.motion_flow.SceneFlow`,
each one pass over the HQ depth samples (the numpy version made ~15 full-image temporaries: it cost three
plain warps, and issue 12 asks the corrected warp for at least half the plain warp's throughput); between
them :func:`flow_gain` chooses the factor on the optical flow. :func:`fill_untrusted` is the fill of
untrusted samples by the mean motion of the trusted ones of their own surface around them;
:func:`expand_blocks` the motion of every sample from the block samples'. Motions are written
planar, ``(C, Hs, Ws)``: rotated by ``R`` (``C = 3``; ``R = I``: the source frame), or with the
source-frame depth change as a fourth channel (``C = 4``): :class:`align.warp.CropMotion`'s layout,
so the warp takes them as they are (no image of motions, no rotation of one).
"""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, inline="always")
def _cell(x, y, H, W):  # pragma: no cover - compiled
    """The bilinear cell of ``(x, y)``: ``(x0, y0, fx, fy)``, ``x0 = -1`` outside ``[0, W-1] x [0, H-1]``."""
    if not (0.0 <= x <= W - 1 and 0.0 <= y <= H - 1):
        return -1, 0, np.float32(0), np.float32(0)
    x0, y0 = min(np.int32(x), np.int32(W - 2)), min(np.int32(y), np.int32(H - 2))
    return x0, y0, np.float32(x - x0), np.float32(y - y0)


@numba.njit(cache=True, nogil=True, inline="always")
def _lerp(img, x0, y0, fx, fy, c):  # pragma: no cover - compiled
    """Channel ``c`` of ``img`` ``(H, W, C)`` interpolated in the cell ``(x0, y0, fx, fy)`` of :func:`_cell`."""
    top = img[y0, x0, c] * (1 - fx) + img[y0, x0 + 1, c] * fx
    return top * (1 - fy) + (img[y0 + 1, x0, c] * (1 - fx) + img[y0 + 1, x0 + 1, c] * fx) * fy


#: fastmath without its no-NaN / no-infinity assumptions (depths are NaN where none): reciprocals and fused
#: multiply-adds (scene_shift 1.1 -> 0.7 ms per pair, session 9)
_FAST = {"arcp", "contract", "afn", "reassoc", "nsz"}


@numba.njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST)
def scene_shift(d, flow, cams, grid, shift, has):  # pragma: no cover - compiled
    """Steps 1-2 of :class:`align.motion_flow.SceneFlow` for the samples ``(r0 + i stride, c0 + j stride)``
    of HQ frame ``o``, ``grid = (r0, c0, stride)``: each one's optical flow in depth pixels.

    Args:
        d: depth of frame ``o``, ``(H, W)`` float32 metres (NaN or <= 0 = none).
        flow: the optical flow on the reduced colour image, ``(h, w, 2)`` float32 pixels.
        cams: ``(rays, Rr, t, kc, to_depth, kd, colour_uv)``: the depth camera's undistorted rays
            ``(H, W, 2)`` (x, y at z = 1); ``Rr`` ``(3, H, W)`` the rays rotated into the colour camera and
            ``t`` ``(3,)``; ``kc`` ``(fx, fy, cx, cy, s)`` the colour pinhole and the flow image's reduction;
            ``to_depth`` ``(2,)`` flow pixels to depth pixels; ``kd`` ``(fx, fy, cx, cy)`` of a pinhole
            depth camera or ``(0,)`` (lens distortion: the ray through ``q`` interpolated in ``rays``);
            ``colour_uv`` ``(2, H, W)`` positions on the flow image computed outside (a colour camera
            with lens distortion) or ``(2, 0, 0)`` (pinhole: computed here). All float32.
    Writes ``shift`` ``(Hs, Ws, 2)`` float32, the flow in depth pixels (``q - p``; 0 where none), and ``has``
    ``(Hs, Ws)`` bool: the sample has depth and its colour position lies within the flow image.
    """
    rays, Rr, t, kc, to_depth, kd, colour_uv = cams
    r0, c0, stride = grid
    h, w = flow.shape[0], flow.shape[1]
    half, one, zero = np.float32(0.5), np.float32(1), np.float32(0)
    fxc, fyc, cxc, cyc, s = kc[0], kc[1], kc[2], kc[3], kc[4]
    t0, t1, t2, k0, k1 = t[0], t[1], t[2], to_depth[0], to_depth[1]
    pinhole = colour_uv.shape[1] == 0
    for i in range(has.shape[0]):
        y = r0 + i * stride
        for j in range(has.shape[1]):
            x = c0 + j * stride
            z = d[y, x]
            s0, s1, ok = zero, zero, False
            if z > 0:
                u = v = np.float32(-1)  # behind the colour camera: outside its image
                if pinhole:
                    Zc = z * Rr[2, y, x] + t2
                    if Zc > 0:
                        iz = one / Zc
                        u = ((z * Rr[0, y, x] + t0) * iz * fxc + cxc + half) * s - half
                        v = ((z * Rr[1, y, x] + t1) * iz * fyc + cyc + half) * s - half
                else:
                    u, v = colour_uv[0, y, x], colour_uv[1, y, x]
                x0, y0, fx, fy = _cell(u, v, h, w)
                if x0 >= 0:  # inside the colour image
                    s0 = _lerp(flow, x0, y0, fx, fy, 0) * k0
                    s1 = _lerp(flow, x0, y0, fx, fy, 1) * k1
                    ok = True
            shift[i, j, 0], shift[i, j, 1], has[i, j] = s0, s1, ok


#: The landing rule, written out where it is used (scene_motion, flow_gain, expand_blocks): a sample at ``(x, y)``
#: moved by ``(sx, sy)`` falls in the pixel ``(int(x + sx + 0.5), int(y + sy + 0.5))`` when that lies in the image,
#: and lands on its own surface when the other frame's depth there is within ``max_jump`` of its own. float32
#: throughout and truncation of the non-negative (float64 and ``floor`` cost four times as much in these loops).


@numba.njit(cache=True, nogil=True, error_model="numpy")
def flow_gain(d, dx, shift, has, grid, gains, max_jump, min_px):  # pragma: no cover - compiled
    """``(index, landed, moving)``: the index into ``gains`` ``(G,)`` float32 of the factor on the samples' flow
    ``shift`` (:func:`scene_shift`) that carries the most of the ``moving`` samples (flow over ``min_px``)
    onto their own surface in ``dx`` (depth within ``max_jump``; the count of those that land on it minus
    those that do not, the first of equal counts), and how many ``landed`` with it."""
    r0, c0, stride = grid
    n, m = 0, has.shape[0] * has.shape[1]
    moving = np.empty((5, m), np.float32)  # the moving samples' x, y, depth and shift, contiguous
    px, py, pz, sxs, sys = moving[0], moving[1], moving[2], moving[3], moving[4]
    for i in range(has.shape[0]):
        for j in range(has.shape[1]):
            sx, sy = shift[i, j, 0], shift[i, j, 1]
            if has[i, j] and sx * sx + sy * sy > min_px * min_px:
                y, x = r0 + i * stride, c0 + j * stride
                px[n], py[n], pz[n], sxs[n], sys[n] = x + np.float32(0.5), y + np.float32(0.5), d[y, x], sx, sy
                n += 1
    H, W = d.shape
    best, best_n = 0, -(1 << 62)
    for g in range(gains.size):
        count = 0
        for k in range(n):  # the landing rule
            qx, qy = px[k] + gains[g] * sxs[k], py[k] + gains[g] * sys[k]
            ok = qx >= 0 and qy >= 0 and qx < W and qy < H and abs(dx[np.int64(qy), np.int64(qx)] - pz[k]) <= max_jump
            count += 1 if ok else -1
        if count > best_n:
            best, best_n = g, count
    return best, (best_n + n) // 2, n


@numba.njit(cache=True, nogil=True, error_model="numpy")
def scene_motion(d, dx, shift, has, cams, R, grid, scale, max_jump, still_px, still_dz, out, trusted, still):  # pragma: no cover - compiled
    """Step 3 of :class:`align.motion_flow.SceneFlow` for :func:`scene_shift`'s samples: each one carried by
    its ``shift`` to ``q`` in frame ``x``, trusted where ``dx`` there is within ``max_jump`` of its depth, its
    motion ``P_x - P``.

    Args:
        d, dx: depth of frames ``o`` and ``x``, ``(H, W)`` float32 metres (NaN or <= 0 = none).
        shift, has: :func:`scene_shift`'s (the flow in depth pixels, times the flow's gain).
        cams, grid: as :func:`scene_shift`'s.
        R: ``(3, 3)`` float32, the rotation the motion is written in (the identity: ``o``'s depth camera).
        scale: float32, the motion written is this fraction of the motion to frame ``x``.
        max_jump: float32 metres, the largest depth change of a trusted target.
        still_px, still_dz: float32 depth pixels and metres: a trusted sample whose flow is no longer and
            whose target's depth is within ``still_dz`` of its own stands still (``still``, motion 0: what is
            left is the two frames' depth noise, and moving it by ``scale`` of under a pixel changes nothing).
    Writes ``out`` ``(C, Hs, Ws)`` float32 (``R m``, and ``m_z`` when ``C = 4``; 0 where untrusted or still),
    ``trusted`` and ``still`` ``(Hs, Ws)`` bool.
    """
    rays, kd = cams[0], cams[5]
    H, W = d.shape
    r0, c0, stride = grid
    C = out.shape[0]
    pinhole = kd.size > 0
    one, zero, half = np.float32(1), np.float32(0), np.float32(0.5)
    fxd, fyd, cxd, cyd = (kd[0], kd[1], kd[2], kd[3]) if pinhole else (one, one, zero, zero)
    R00, R01, R02 = R[0, 0], R[0, 1], R[0, 2]
    R10, R11, R12 = R[1, 0], R[1, 1], R[1, 2]
    R20, R21, R22 = R[2, 0], R[2, 1], R[2, 2]
    sp2, Wf, Hf, Wm, Hm = still_px * still_px, np.float32(W), np.float32(H), np.float32(W - 1), np.float32(H - 1)
    for i in range(trusted.shape[0]):
        y = r0 + i * stride
        for j in range(trusted.shape[1]):
            x = c0 + j * stride
            o0 = o1 = o2 = o3 = zero
            tr = st = False
            if has[i, j]:
                sx, sy = shift[i, j, 0], shift[i, j, 1]
                qx, qy = np.float32(x) + sx + half, np.float32(y) + sy + half  # the landing rule
                if qx >= 0 and qy >= 0 and qx < Wf and qy < Hf:
                    z, zq = d[y, x], dx[np.int64(qy), np.int64(qx)]
                    if abs(zq - z) <= max_jump:
                        tr = True
                        st = sx * sx + sy * sy <= sp2 and abs(zq - z) <= still_dz  # stands still
                        if not st:
                            px, py = min(max(x + sx, zero), Wm), min(max(y + sy, zero), Hm)
                            if pinhole:  # the ray through q (within the image)
                                rxq, ryq = (px - cxd) / fxd, (py - cyd) / fyd
                            else:  # interpolated (lens distortion)
                                x0, y0, fx, fy = _cell(px, py, H, W)
                                rxq, ryq = _lerp(rays, x0, y0, fx, fy, 0), _lerp(rays, x0, y0, fx, fy, 1)
                            m0, m1 = (rxq * zq - z * rays[y, x, 0]) * scale, (ryq * zq - z * rays[y, x, 1]) * scale
                            o3 = (zq - z) * scale
                            o0 = R00 * m0 + R01 * m1 + R02 * o3
                            o1 = R10 * m0 + R11 * m1 + R12 * o3
                            o2 = R20 * m0 + R21 * m1 + R22 * o3
            out[0, i, j], out[1, i, j], out[2, i, j] = o0, o1, o2
            if C == 4:
                out[3, i, j] = o3
            trusted[i, j], still[i, j] = tr, st


@numba.njit(cache=True, nogil=True)
def block_depths(d, grid, shape):  # pragma: no cover - compiled
    """The depths ``(Hs, Ws)`` float32 of the samples ``(r0 + i stride, c0 + j stride)`` of ``d`` (contiguous)."""
    r0, c0, stride = grid
    dl = np.empty(shape, np.float32)
    for i in range(shape[0]):
        for j in range(shape[1]):
            dl[i, j] = d[r0 + i * stride, c0 + j * stride]
    return dl


@numba.njit(cache=True, nogil=True)
def fill_offsets(radius):  # pragma: no cover - compiled
    """The window :func:`fill_untrusted` looks in, ``(K, 2)`` int64 row and column offsets: every offset
    within 2 and every other one (even rows and columns) out to ``radius`` (a third of the square's)."""
    out = np.empty(((2 * radius + 1) ** 2, 2), np.int64)
    k = 0
    for a in range(-radius, radius + 1):
        for b in range(-radius, radius + 1):
            if (abs(a) <= 2 and abs(b) <= 2) or (a % 2 == 0 and b % 2 == 0):
                out[k, 0], out[k, 1] = a, b
                k += 1
    return out[:k]


@numba.njit(cache=True, nogil=True)
def fill_untrusted(out, trusted, offsets, dl, max_jump):  # pragma: no cover - compiled
    """In place: each untrusted sample of ``out`` ``(C, Hs, Ws)`` with depth (``dl`` ``(Hs, Ws)``, the samples'
    depths, :func:`block_depths`) takes the mean motion of the trusted samples at ``offsets`` around it
    (:func:`fill_offsets`) that lie on its own surface (depth within ``max_jump``: a silhouette's
    untrusted samples take their own body's motion, not the background's), 0 where there are none."""
    C = out.shape[0]
    Hs, Ws = trusted.shape
    tz = np.empty((Hs, Ws), np.float32)  # a trusted sample's depth, NaN elsewhere: one read per neighbour
    for i in range(Hs):
        for j in range(Ws):
            tz[i, j] = dl[i, j] if trusted[i, j] else np.float32(np.nan)
    K, r = offsets.shape[0], 0
    for k in range(K):
        r = max(r, abs(offsets[k, 0]), abs(offsets[k, 1]))
    for i in range(Hs):
        for j in range(Ws):
            z = dl[i, j]
            if trusted[i, j] or not z > 0:
                continue
            a0 = a1 = a2 = a3 = np.float32(0)
            n = 0
            inner = r <= i < Hs - r and r <= j < Ws - r  # the whole window within the samples: no bounds test
            for k in range(K):
                a, b = i + offsets[k, 0], j + offsets[k, 1]
                if (inner or (0 <= a < Hs and 0 <= b < Ws)) and abs(tz[a, b] - z) <= max_jump:
                    a0, a1, a2 = a0 + out[0, a, b], a1 + out[1, a, b], a2 + out[2, a, b]
                    if C == 4:
                        a3 += out[3, a, b]
                    n += 1
            if n > 0:
                out[0, i, j], out[1, i, j], out[2, i, j] = a0 / n, a1 / n, a2 / n
                if C == 4:
                    out[3, i, j] = a3 / n


@numba.njit(cache=True, nogil=True, error_model="numpy")
def expand_blocks(low, trusted, still, shift, dl, d, dx, R, grid, corner, scale, max_jump, out):  # pragma: no cover - compiled
    """Every sample ``(r0 + y, c0 + x)`` of ``d`` ``(H, W)`` (``corner = (r0, c0)``) takes the motion of the
    block samples around it (``low`` ``(C, Hs, Ws)`` of :func:`scene_motion` with ``stride``, filled;
    ``grid = (g0, h0, stride)`` its origin; ``dl`` their depths, :func:`block_depths`): their bilinear mean over those on its surface (depth within
    ``max_jump`` of its own; none such: its own block's), so that a block across a silhouette does not
    give one side the other's motion. Its depth change is its own where one of them was trusted and not
    ``still``: ``dx`` at the sample moved by their mean ``shift`` (within ``max_jump``), times ``scale`` (a
    block's would add its sample's depth noise to the whole block); it enters the motion through ``R[:, 2]``
    (the motion is linear in it). Where every block sample around it is still, its motion is 0 (what the
    rest gives there, without the work: much of a scene stands still), and where it has no depth, 0 (the
    warp does not move what is not there). Writes ``out`` ``(C, Hc, Wc)`` float32."""
    g0, h0, stride = grid
    r0, c0 = corner
    H, W = d.shape
    C = out.shape[0]
    Hs, Ws = trusted.shape
    inv, half = np.float32(1) / stride, np.float32(0.5)
    # tables, not a division per sample (an integer division costs more than the rest of a sample's work)
    jx = np.empty(out.shape[2], np.int64)
    wxs = np.empty(out.shape[2], np.float32)
    for x in range(out.shape[2]):
        jx[x] = (c0 + x - h0) // stride
        wxs[x] = np.float32((c0 + x - h0) % stride) * inv
    out[...] = 0  # one contiguous fill; still pixels then skip (0.3 ms less than writing each one's four zeros)
    for y in range(out.shape[1]):
        Y = r0 + y
        i = (Y - g0) // stride
        wy = np.float32((Y - g0) % stride) * inv
        for x in range(out.shape[2]):
            X = c0 + x
            j = jx[x]
            z = d[Y, X]
            wx = wxs[x]
            if not z > 0 or (still[i, j] and (wx == 0 or j + 1 >= Ws or still[i, j + 1])
                    and (wy == 0 or i + 1 >= Hs or (still[i + 1, j] and (wx == 0 or j + 1 >= Ws or still[i + 1, j + 1])))):
                continue  # 0, written above
            a0 = a1 = a2 = a3 = wsum = tsum = sx = sy = np.float32(0)
            for di in range(2):
                ii = i + di
                wi = wy if di else np.float32(1) - wy  # float32 throughout (1 - wy would be float64)
                if not (wi > 0 and ii < Hs):
                    continue
                for dj in range(2):
                    jj = j + dj
                    w = wi * (wx if dj else np.float32(1) - wx)
                    if not (w > 0 and jj < Ws and abs(dl[ii, jj] - z) <= max_jump):
                        continue
                    wsum += w
                    a0, a1, a2 = a0 + w * low[0, ii, jj], a1 + w * low[1, ii, jj], a2 + w * low[2, ii, jj]
                    if C == 4:
                        a3 += w * low[3, ii, jj]
                    if trusted[ii, jj] and not still[ii, jj]:
                        tsum, sx, sy = tsum + w, sx + w * shift[ii, jj, 0], sy + w * shift[ii, jj, 1]
            if not wsum > 0:  # on no block sample's surface: its own block's
                for c in range(C):
                    out[c, y, x] = low[c, i, j]
                continue
            a0, a1, a2, a3 = a0 / wsum, a1 / wsum, a2 / wsum, a3 / wsum
            if tsum > 0:
                qx, qy = np.float32(X) + half + sx / tsum, np.float32(Y) + half + sy / tsum  # the landing rule
                zq = dx[np.int64(qy), np.int64(qx)] if qx >= 0 and qy >= 0 and qx < W and qy < H else np.float32(np.nan)
                if abs(zq - z) <= max_jump:
                    m2 = a3 if C == 4 else a0 * R[0, 2] + a1 * R[1, 2] + a2 * R[2, 2]
                    delta = (zq - z) * scale - m2  # R is orthonormal: m_z = R[:, 2] . (R m)
                    a0, a1, a2, a3 = a0 + R[0, 2] * delta, a1 + R[1, 2] * delta, a2 + R[2, 2] * delta, a3 + delta
            out[0, y, x], out[1, y, x], out[2, y, x] = a0, a1, a2
            if C == 4:
                out[3, y, x] = a3
