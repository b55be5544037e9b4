"""The compiled passes of :mod:`align.motion_flow` (imported on first use: numba takes a while to import).

:func:`scene_motion` is steps 1-3 of :class:`align.motion_flow.SceneFlow` in one pass over the HQ depth
samples (the numpy version made ~15 full-image temporaries: it cost three plain warps, and issue 12 asks
the corrected warp for at least half the plain warp's throughput); :func:`fill_untrusted` is the fill of
untrusted samples by the mean motion of the trusted ones around them, by running box sums (two passes).
Motions are written
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


@numba.njit(cache=True, nogil=True, error_model="numpy")
def scene_motion(d, dx, flow, cams, R, grid, scale, max_jump, out, trusted, shift, ubox):  # pragma: no cover - compiled
    """Steps 1-3 of :class:`align.motion_flow.SceneFlow` for the samples ``(r0 + i stride, c0 + j stride)``
    of HQ frame ``o``, ``grid = (r0, c0, stride)``.

    Args:
        d, dx: depth of frames ``o`` and ``x``, ``(H, W)`` float32 metres (NaN or <= 0 = none).
        flow: the optical flow on the reduced colour image, ``(h, w, 2)`` float32 pixels.
        cams: ``(rays, Rr, t, kc, to_depth, kd, colour_uv)``: the depth camera's undistorted rays
            ``(H, W, 2)`` (x, y at z = 1); ``Rr`` ``(3, H, W)`` the rays rotated into the colour camera and
            ``t`` ``(3,)``; ``kc`` ``(fx, fy, cx, cy, s)`` the colour pinhole and the flow image's reduction;
            ``to_depth`` ``(2,)`` flow pixels to depth pixels; ``kd`` ``(fx, fy, cx, cy)`` of a pinhole
            depth camera or ``(0,)`` (lens distortion: the ray through ``q`` interpolated in ``rays``);
            ``colour_uv`` ``(2, H, W)`` positions on the flow image computed outside (a colour camera
            with lens distortion) or ``(2, 0, 0)`` (pinhole: computed here). All float32.
        R: ``(3, 3)`` float32, the rotation the motion is written in (the identity: ``o``'s depth camera).
        scale: float32, the motion written is this fraction of the motion to frame ``x``.
        max_jump: float32 metres, the largest depth change of a trusted target.
    Writes ``out`` ``(C, Hs, Ws)`` float32 (``R m``, and ``m_z`` when ``C = 4``; 0 where untrusted),
    ``trusted`` ``(Hs, Ws)`` bool, ``shift`` ``(Hs, Ws, 2)`` float32 the flow in depth pixels (``q - p``)
    and ``ubox`` ``(4,)`` int64, the rows ``[0, 1)`` and columns ``[2, 3)`` of the untrusted samples with
    depth (empty: ``ubox[0] >= ubox[1]``).
    """
    rays, Rr, t, kc, to_depth, kd, colour_uv = cams
    H, W = d.shape
    r0, c0, stride = grid
    h, w = flow.shape[0], flow.shape[1]
    half = np.float32(0.5)
    out[:] = 0
    shift[:] = 0
    trusted[:] = False
    ubox[0], ubox[1], ubox[2], ubox[3] = trusted.shape[0], 0, trusted.shape[1], 0
    for i in range(trusted.shape[0]):
        for j in range(trusted.shape[1]):
            y, x = r0 + i * stride, c0 + j * stride
            z = d[y, x]
            if not z > 0:
                continue
            if colour_uv.shape[1] == 0:
                Zc = z * Rr[2, y, x] + t[2]
                u = v = np.float32(-1)  # behind the colour camera: outside its image
                if Zc > 0:
                    u = ((z * Rr[0, y, x] + t[0]) / Zc * kc[0] + kc[2] + half) * kc[4] - half
                    v = ((z * Rr[1, y, x] + t[1]) / Zc * kc[1] + kc[3] + half) * kc[4] - half
            else:
                u, v = colour_uv[0, y, x], colour_uv[1, y, x]
            x0, y0, fx, fy = _cell(u, v, h, w)
            ok = x0 >= 0  # inside the colour image
            if ok:
                shift[i, j, 0] = _lerp(flow, x0, y0, fx, fy, 0) * to_depth[0]
                shift[i, j, 1] = _lerp(flow, x0, y0, fx, fy, 1) * to_depth[1]
                qx, qy = x + shift[i, j, 0], y + shift[i, j, 1]
                ix, iy = np.int32(np.floor(qx + half)), np.int32(np.floor(qy + half))
                ok = 0 <= ix < W and 0 <= iy < H and abs(dx[min(max(iy, 0), H - 1), min(max(ix, 0), W - 1)] - z) <= max_jump
            if not ok:
                ubox[0], ubox[1] = min(ubox[0], i), max(ubox[1], i + 1)
                ubox[2], ubox[3] = min(ubox[2], j), max(ubox[3], j + 1)
                continue
            zq = dx[iy, ix]
            qx, qy = min(max(qx, np.float32(0)), np.float32(W - 1)), min(max(qy, np.float32(0)), np.float32(H - 1))
            if kd.size:  # the ray through q (within the image)
                rxq, ryq = (qx - kd[2]) / kd[0], (qy - kd[3]) / kd[1]
            else:  # interpolated (lens distortion)
                x0, y0, fx, fy = _cell(qx, qy, H, W)
                rxq, ryq = _lerp(rays, x0, y0, fx, fy, 0), _lerp(rays, x0, y0, fx, fy, 1)
            trusted[i, j] = True
            m0, m1, m2 = (rxq * zq - z * rays[y, x, 0]) * scale, (ryq * zq - z * rays[y, x, 1]) * scale, (zq - z) * scale
            for c in range(3):
                out[c, i, j] = R[c, 0] * m0 + R[c, 1] * m1 + R[c, 2] * m2
            if out.shape[0] == 4:
                out[3, i, j] = m2


@numba.njit(cache=True, nogil=True)
def fill_untrusted(out, trusted, radius, box, depth_only, d, grid):  # pragma: no cover - compiled
    """In place: each untrusted sample of ``out`` ``(C, Hs, Ws)`` within ``box`` (rows ``[box[0], box[1])``,
    columns ``[box[2], box[3])``; with ``depth_only``, only those whose sample of ``d`` ``(H, W)`` has
    depth, ``grid = (r0, c0, stride)`` as :func:`scene_motion`'s) takes the mean of the trusted samples
    within ``radius`` (a ``(2 radius + 1)`` box), 0 where there are none. Running sums over the box grown
    by ``radius``, rows then columns: the cost does not grow with ``radius``."""
    C = out.shape[0]
    Hs, Ws = trusted.shape
    g0, h0, st = grid
    r0, r1 = max(box[0] - radius, 0), min(box[1] + radius, Hs)
    c0, c1 = max(box[2] - radius, 0), min(box[3] + radius, Ws)
    if r0 >= r1 or c0 >= c1:
        return
    H, W = r1 - r0, c1 - c0
    acc = np.zeros((H, W, C + 1), np.float32)  # per row: box sums along x of (motion, trusted)
    for y in range(H):
        run = np.zeros(C + 1, np.float32)
        for x in range(-radius, W + radius):
            if x + radius < W and trusted[r0 + y, c0 + x + radius]:
                for c in range(C):
                    run[c] += out[c, r0 + y, c0 + x + radius]
                run[C] += 1
            if x - radius - 1 >= 0 and trusted[r0 + y, c0 + x - radius - 1]:
                for c in range(C):
                    run[c] -= out[c, r0 + y, c0 + x - radius - 1]
                run[C] -= 1
            if 0 <= x < W:
                acc[y, x] = run
    col = np.zeros((W, C + 1), np.float32)  # box sums along y of the row sums, for row y
    for y in range(-radius, H + radius):
        if y + radius < H:
            col += acc[y + radius]
        if y - radius - 1 >= 0:
            col -= acc[y - radius - 1]
        if 0 <= y < H and box[0] <= r0 + y < box[1]:
            for x in range(max(box[2] - c0, 0), min(box[3] - c0, W)):
                yy, xx = r0 + y, c0 + x
                if not trusted[yy, xx] and col[x, C] > 0.5 and (not depth_only or d[g0 + yy * st, h0 + xx * st] > 0):
                    for c in range(C):
                        out[c, yy, xx] = col[x, c] / col[x, C]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def expand_blocks(low, trusted, shift, d, dx, R, grid, corner, scale, max_jump, out):  # pragma: no cover - compiled
    """Every sample ``(r0 + y, c0 + x)`` of ``d`` ``(H, W)`` (``corner = (r0, c0)``) takes the motion of the
    block samples around it (``low`` ``(C, Hs, Ws)`` of :func:`scene_motion` with ``stride``, filled;
    ``grid = (g0, h0, stride)`` its origin): their bilinear mean over those on its surface (depth within
    ``max_jump`` of its own; none such: its own block's), so that a block across a silhouette does not
    give one side the other's motion. Its depth change is its own where one of them was trusted: ``dx``
    at the sample moved by their mean ``shift`` (within ``max_jump``), times ``scale`` (a block's would add
    its sample's depth noise to the whole block); it enters the motion through ``R[:, 2]`` (the motion is
    linear in it). Writes ``out`` ``(C, Hc, Wc)`` float32."""
    g0, h0, stride = grid
    r0, c0 = corner
    H, W = d.shape
    C = out.shape[0]
    Hs, Ws = trusted.shape
    inv = np.float32(1) / stride
    for y in range(out.shape[1]):
        Y = r0 + y
        i = (Y - g0) // stride
        wy = np.float32((Y - g0) % stride) * inv
        for x in range(out.shape[2]):
            X = c0 + x
            j = (X - h0) // stride
            z = d[Y, X]
            wx = np.float32((X - h0) % stride) * inv
            a0 = a1 = a2 = a3 = wsum = tsum = sx = sy = np.float32(0)
            for di in range(2):
                ii = i + di
                wi = wy if di else 1 - wy
                if not (wi > 0 and ii < Hs):
                    continue
                for dj in range(2):
                    jj = j + dj
                    w = wi * (wx if dj else 1 - wx)
                    if not (w > 0 and jj < Ws and abs(d[g0 + ii * stride, h0 + jj * stride] - z) <= max_jump):
                        continue
                    wsum += w
                    a0, a1, a2 = a0 + w * low[0, ii, jj], a1 + w * low[1, ii, jj], a2 + w * low[2, ii, jj]
                    if C == 4:
                        a3 += w * low[3, ii, jj]
                    if trusted[ii, jj]:
                        tsum, sx, sy = tsum + w, sx + w * shift[ii, jj, 0], sy + w * shift[ii, jj, 1]
            if not wsum > 0:  # on no block sample's surface: its own block's
                for c in range(C):
                    out[c, y, x] = low[c, i, j]
                continue
            a0, a1, a2, a3 = a0 / wsum, a1 / wsum, a2 / wsum, a3 / wsum
            if tsum > 0:
                ix = np.int32(np.floor(X + sx / tsum + np.float32(0.5)))
                iy = np.int32(np.floor(Y + sy / tsum + np.float32(0.5)))
                if 0 <= ix < W and 0 <= iy < H and abs(dx[iy, ix] - z) <= max_jump:
                    m2 = a3 if C == 4 else a0 * R[0, 2] + a1 * R[1, 2] + a2 * R[2, 2]
                    delta = (dx[iy, ix] - z) * scale - m2  # R is orthonormal: m_z = R[:, 2] . (R m)
                    a0, a1, a2, a3 = a0 + R[0, 2] * delta, a1 + R[1, 2] * delta, a2 + R[2, 2] * delta, a3 + delta
            out[0, y, x], out[1, y, x], out[2, y, x] = a0, a1, a2
            if C == 4:
                out[3, y, x] = a3
