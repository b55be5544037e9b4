"""The compiled passes of :mod:`align.motion_flow` (imported on first use: numba takes a while to import).

:func:`scene_motion` is steps 1-3 of :class:`align.motion_flow.SceneFlow` in one pass over the HQ depth
samples (the numpy version made ~15 full-image temporaries: it cost three plain warps, and issue 12 asks
the corrected warp for at least half the plain warp's throughput); :func:`fill_untrusted` is the fill of
untrusted samples by the mean motion of the trusted ones around them, by running box sums (two passes).
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
def scene_motion(d, dx, flow, region, rays, Rr, t, kc, to_depth, kd, colour_uv, scale, max_jump, stride, motion,
                 trusted, shift, ubox):  # pragma: no cover - compiled
    """Steps 1-3 of :class:`align.motion_flow.SceneFlow` for every sample of HQ frame ``o``.

    Args:
        d, dx: depth of frames ``o`` and ``x``, ``(H, W)`` float32 metres (NaN or <= 0 = none).
        flow: the optical flow on the reduced colour image's moving region, ``(hr, wr, 2)`` float32 pixels.
        region: ``(x0, y0, w, h)`` int64: the region's corner on the reduced colour image and that
            image's size. A sample inside the image but outside the region (outside its bilinear
            interior) is still: motion 0, trusted.
        rays: the depth camera's undistorted rays (x, y at z = 1), ``(H, W, 2)`` float32.
        Rr: ``(3, H, W)`` float32, the rays rotated into the colour camera (``R ray``); ``t`` ``(3,)``.
        kc: ``(fx, fy, cx, cy, s)`` float32, the colour camera's pinhole and the flow image's reduction.
        to_depth: ``(2,)`` float32, flow pixels to depth pixels (``fx_depth / fx_colour / s``, same for y).
        kd: ``(fx, fy, cx, cy)`` float32 of a pinhole depth camera (the ray through ``q`` computed), or
            ``(0,)``: lens distortion, the ray through ``q`` interpolated in ``rays``.
        colour_uv: ``(2, H, W)`` float32 positions on the reduced colour image computed outside (a
            colour camera with lens distortion), or ``(2, 0, 0)``: pinhole, computed here.
        scale: float32, the motion written is this fraction of the motion to frame ``x``.
        max_jump: float32 metres, the largest depth change of a trusted target.
        stride: every ``stride``-th sample along each axis (its motion stands for its block's).
    Writes ``motion`` ``(Hs, Ws, 3)`` float32 (0 where untrusted), ``trusted`` ``(Hs, Ws)`` bool and
    ``shift`` ``(Hs, Ws, 2)`` float32, the flow in depth pixels (``q - p``), ``Hs = ceil(H / stride)``:
    entry ``[i, j]`` is sample ``(i stride, j stride)``'s; ``ubox`` ``(4,)`` int64, the rows ``[0, 1)``
    and columns ``[2, 3)`` of the untrusted samples with depth (empty: ``ubox[0] >= ubox[1]``).
    """
    H, W = d.shape
    hr, wr = flow.shape[0], flow.shape[1]
    half = np.float32(0.5)
    to_x, to_y = to_depth[0], to_depth[1]
    ubox[0], ubox[1], ubox[2], ubox[3] = trusted.shape[0], 0, trusted.shape[1], 0
    for i in range(trusted.shape[0]):
        for j in range(trusted.shape[1]):
            y, x = i * stride, j * stride
            z = d[y, x]
            trusted[i, j] = False
            motion[i, j, 0] = motion[i, j, 1] = motion[i, j, 2] = 0
            shift[i, j, 0] = shift[i, j, 1] = 0
            if not z > 0:
                continue
            if _sample_motion(d, dx, flow, region, rays, Rr, t, kc, kd, colour_uv, scale, max_jump, y, x, i, j,
                              to_x, to_y, hr, wr, half, motion, trusted, shift):
                continue
            ubox[0], ubox[1] = min(ubox[0], i), max(ubox[1], i + 1)
            ubox[2], ubox[3] = min(ubox[2], j), max(ubox[3], j + 1)


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _sample_motion(d, dx, flow, region, rays, Rr, t, kc, kd, colour_uv, scale, max_jump, y, x, i, j, to_x, to_y, hr,
                   wr, half, motion, trusted, shift):  # pragma: no cover - compiled
    """One sample of :func:`scene_motion` (it has depth ``z > 0``); returns whether it is trusted."""
    H, W = d.shape
    z = d[y, x]
    if colour_uv.shape[1] == 0:
        Zc = z * Rr[2, y, x] + t[2]
        if not Zc > 0:
            return False
        u = ((z * Rr[0, y, x] + t[0]) / Zc * kc[0] + kc[2] + half) * kc[4] - half
        v = ((z * Rr[1, y, x] + t[1]) / Zc * kc[1] + kc[3] + half) * kc[4] - half
    else:
        u, v = colour_uv[0, y, x], colour_uv[1, y, x]
    if not (0.0 <= u <= region[2] - 1 and 0.0 <= v <= region[3] - 1):
        return False  # outside the colour image
    x0, y0, fx, fy = _cell(u - region[0], v - region[1], hr, wr)
    if x0 < 0:  # outside the moving region: still
        trusted[i, j] = True
        return True
    shift[i, j, 0] = _lerp(flow, x0, y0, fx, fy, 0) * to_x
    shift[i, j, 1] = _lerp(flow, x0, y0, fx, fy, 1) * to_y
    qx, qy = x + shift[i, j, 0], y + shift[i, j, 1]
    ix, iy = np.int32(np.floor(qx + half)), np.int32(np.floor(qy + half))
    if not (0 <= ix < W and 0 <= iy < H):
        return False
    zq = dx[iy, ix]
    if not abs(zq - z) <= max_jump:
        return False
    qx, qy = min(max(qx, np.float32(0)), np.float32(W - 1)), min(max(qy, np.float32(0)), np.float32(H - 1))
    if kd.size:  # the ray through q (within the image)
        rxq, ryq = (qx - kd[2]) / kd[0], (qy - kd[3]) / kd[1]
    else:  # interpolated (lens distortion)
        x0, y0, fx, fy = _cell(qx, qy, H, W)
        rxq, ryq = _lerp(rays, x0, y0, fx, fy, 0), _lerp(rays, x0, y0, fx, fy, 1)
    trusted[i, j] = True
    motion[i, j, 0] = (rxq * zq - z * rays[y, x, 0]) * scale
    motion[i, j, 1] = (ryq * zq - z * rays[y, x, 1]) * scale
    motion[i, j, 2] = (zq - z) * scale
    return True


@numba.njit(cache=True, nogil=True)
def fill_untrusted(motion, trusted, radius, box, depth_only, d, stride):  # pragma: no cover - compiled
    """In place: each untrusted sample of ``motion`` ``(Hs, Ws, 3)`` within ``box`` (rows ``[box[0],
    box[1])``, columns ``[box[2], box[3])``; with ``depth_only``, only those whose sample of ``d``
    ``(H, W)`` at ``(i stride, j stride)`` has depth) takes the mean motion of the trusted samples
    within ``radius`` (a ``(2 radius + 1)`` box), 0 where there are none. Running sums over the box
    grown by ``radius``, rows then columns: the cost does not grow with ``radius``."""
    Hs, Ws = trusted.shape
    r0, r1 = max(box[0] - radius, 0), min(box[1] + radius, Hs)
    c0, c1 = max(box[2] - radius, 0), min(box[3] + radius, Ws)
    if r0 >= r1 or c0 >= c1:
        return
    H, W = r1 - r0, c1 - c0
    acc = np.zeros((H, W, 4), np.float32)  # per row: box sums along x of (motion, trusted)
    for y in range(H):
        run = np.zeros(4, np.float32)
        for x in range(-radius, W + radius):
            if x + radius < W and trusted[r0 + y, c0 + x + radius]:
                for c in range(3):
                    run[c] += motion[r0 + y, c0 + x + radius, c]
                run[3] += 1
            if x - radius - 1 >= 0 and trusted[r0 + y, c0 + x - radius - 1]:
                for c in range(3):
                    run[c] -= motion[r0 + y, c0 + x - radius - 1, c]
                run[3] -= 1
            if 0 <= x < W:
                acc[y, x] = run
    col = np.zeros((W, 4), np.float32)  # box sums along y of the row sums, for row y
    for y in range(-radius, H + radius):
        if y + radius < H:
            col += acc[y + radius]
        if y - radius - 1 >= 0:
            col -= acc[y - radius - 1]
        if 0 <= y < H and box[0] <= r0 + y < box[1]:
            for x in range(max(box[2] - c0, 0), min(box[3] - c0, W)):
                yy, xx = r0 + y, c0 + x
                if not trusted[yy, xx] and col[x, 3] > 0.5 and (not depth_only or d[yy * stride, xx * stride] > 0):
                    for c in range(3):
                        motion[yy, xx, c] = col[x, c] / col[x, 3]


@numba.njit(cache=True, nogil=True, inline="always")
def _own_dz(trusted, shift, d, dx, i, j, y, x, scale, max_jump, dz):  # pragma: no cover - compiled
    """Sample ``(y, x)``'s own depth change along its block ``(i, j)``'s shift (``dz``, the block's, where
    the block is untrusted or the target is off the image or another surface), times ``scale``."""
    H, W = d.shape
    z = d[y, x]
    if not (trusted[i, j] and z > 0):
        return dz
    ix = np.int32(np.floor(x + shift[i, j, 0] + np.float32(0.5)))
    iy = np.int32(np.floor(y + shift[i, j, 1] + np.float32(0.5)))
    if 0 <= ix < W and 0 <= iy < H and abs(dx[iy, ix] - z) <= max_jump:
        return (dx[iy, ix] - z) * scale
    return dz


@numba.njit(cache=True, nogil=True)
def expand_blocks(motion, trusted, shift, d, dx, stride, scale, max_jump, out):  # pragma: no cover - compiled
    """Every sample of ``d`` ``(H, W)`` takes its block's motion (``motion`` ``(Hs, Ws, 3)`` of
    :func:`scene_motion` with ``stride``, filled), except for depth: where the block's sample was
    trusted, a sample's depth change is its own, ``dx`` at the sample moved by the block's ``shift``
    (within ``max_jump``; else the block's), times ``scale``: the block's would add its sample's
    depth noise to the whole block. Writes ``out`` ``(H, W, 3)`` float32."""
    H, W = d.shape
    for y in range(H):
        for x in range(W):
            i, j = y // stride, x // stride
            out[y, x, 0], out[y, x, 1] = motion[i, j, 0], motion[i, j, 1]
            out[y, x, 2] = _own_dz(trusted, shift, d, dx, i, j, y, x, scale, max_jump, motion[i, j, 2])


@numba.njit(cache=True, nogil=True)
def crop_motion(motion, trusted, shift, d, dx, stride, scale, max_jump, R, crop, dst, dz):  # pragma: no cover
    """:func:`expand_blocks` over the rows ``[crop[0], crop[1])`` and columns ``[crop[2], crop[3])``
    only, laid out as :class:`align.warp.CropMotion` for a warper with that source crop: ``dst``
    ``(3, N)`` float32 the motion rotated by ``R`` ``(3, 3)`` (into the destination camera), ``dz``
    ``(N,)`` its source-frame depth component, ``N`` the crop's samples, row-major."""
    k = 0
    for y in range(crop[0], crop[1]):
        for x in range(crop[2], crop[3]):
            i, j = y // stride, x // stride
            m0, m1, m2 = motion[i, j, 0], motion[i, j, 1], motion[i, j, 2]
            if stride > 1:
                m2 = _own_dz(trusted, shift, d, dx, i, j, y, x, scale, max_jump, m2)
            dst[0, k] = R[0, 0] * m0 + R[0, 1] * m1 + R[0, 2] * m2
            dst[1, k] = R[1, 0] * m0 + R[1, 1] * m1 + R[1, 2] * m2
            dst[2, k] = R[2, 0] * m0 + R[2, 1] * m1 + R[2, 2] * m2
            dz[k] = m2
            k += 1
