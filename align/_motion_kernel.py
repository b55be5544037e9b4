"""The compiled passes of :mod:`align.motion` (imported on first use: numba takes a while to import).

:func:`rule_one` labels every pixel (one surface in both frames: interpolated; two surfaces: the
edge band); :func:`rule_two` decides the pixels an edge crossed, in place: it lists them, finds
for each the edge's two positions along the direction it moved (:func:`_edge_distances`, the
breadth-first ray search of the first version, each pixel offset looked at once, one call for
all pixels) and takes the frame the edge has passed to. The same references bit for bit as the
first version (numpy bookkeeping around a compiled search), at about half its cost: issue 12
asks the corrected warp for at least half the plain warp's throughput (``perf/reference_motion.py``).
"""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def rule_one(A, B, alpha, edge_rel, own_a, out, band):  # pragma: no cover - compiled
    """Rule 1 of :mod:`align.motion` over the image.

    ``A, B``: ``(H, W)`` float32 metres, NaN = none; ``alpha``, ``edge_rel``: float32. Writes ``out``
    (``(H, W)`` float32): ``A + alpha (B - A)`` where the frames agree within ``edge_rel``, else the
    own frame's (``A`` when ``own_a``); ``band`` (``(H, W)`` uint8): 1 where both frames have depth
    and disagree. Returns the number of interpolated pixels. (No branches in the loop: it vectorises.)
    """
    Af, Bf, of, bf = A.ravel(), B.ravel(), out.ravel(), band.ravel()
    plain = Af if own_a else Bf
    n = 0
    for k in range(Af.size):
        a = Af[k]
        d = Bf[k] - a
        agree = abs(d) <= min(a, Bf[k]) * edge_rel  # false where either is NaN
        of[k] = d * alpha + a if agree else plain[k]
        bf[k] = np.uint8((d == d) and not agree)
        n += agree
    return n


@numba.njit(cache=True, nogil=True)
def rule_two(A, B, band, near_band, alpha, own_a, one_sided, margin, mask_within, rays, out,
             masked):  # pragma: no cover - compiled
    """Rule 2 of :mod:`align.motion` on the pixels of ``band`` and the own frame's one-sided pixels
    where ``near_band`` is set (``(H, W)`` uint8 each; ``near_band`` covers ``band``), in place in
    ``out``; ``masked`` (``(H, W)`` bool, all false on entry) set where the own frame has depth and
    ``out`` has none (only rule 2 takes depth away). Scalars float32 (``one_sided``:
    ``1 + ONE_SIDED_REL``); ``rays``: :func:`step_tables`. Returns ``(crossed, taken_other)``:
    pixels decided, and of those, taking the other frame's surface."""
    idx, mids = _judged(A, B, band, near_band, own_a, one_sided)
    da, db = _edge_distances(A, B, idx, mids, rays)
    Af, Bf, of, mf = A.ravel(), B.ravel(), out.ravel(), masked.ravel()
    half = np.float32(0.5)
    crossed = 0
    taken = 0
    for k in range(idx.size):
        p = idx[k]
        if da[k] < 0 or not np.isfinite(da[k]) or not np.isfinite(db[k]):
            of[p] = np.nan
        else:
            ea = da[k] - half
            passed = alpha * (ea + (db[k] - half)) - ea
            take_b = passed > margin if own_a else passed > -margin
            if mask_within > 0 and abs(passed) < mask_within:
                of[p] = np.nan
            else:
                of[p] = Bf[p] if take_b else Af[p]
                crossed += 1
                if take_b == own_a:
                    taken += 1
        mf[p] = np.isfinite(Af[p] if own_a else Bf[p]) and np.isnan(of[p])
    return crossed, taken


@numba.njit(cache=True, nogil=True)
def _judged(A, B, band, near_band, own_a, one_sided):  # pragma: no cover - compiled
    """The pixels rule 2 judges (flat indices, in raster order) and their midpoint depths: ``band``,
    and where ``near_band`` is set, the own frame's one-sided pixels."""
    Af, Bf, bf, nf = A.ravel(), B.ravel(), band.ravel(), near_band.ravel()
    n = 0
    for p in range(nf.size):
        n += nf[p] != 0
    idx = np.empty(n, np.int64)
    mids = np.empty(n, np.float32)
    n = 0
    for p in range(Af.size):
        if nf[p] == 0:  # no edge within 3 px (near_band covers band)
            continue
        a, b = Af[p], Bf[p]
        if bf[p] != 0 or ((a == a and b != b) if own_a else (b == b and a != a)):
            idx[n] = p
            mids[n] = np.sqrt(a * b) if a == a and b == b else (a if a == a else b) * one_sided
            n += 1
    return idx[:n], mids[:n]


@numba.njit(cache=True, nogil=True)
def _edge_distances(A, B, idx, mids, rays):  # pragma: no cover - compiled
    """Per judged pixel ``idx[k]`` (flat) with midpoint depth ``mids[k]``: the distances (px, between
    pixel centres) to the edge's positions in frames A and B (module docstring of
    :mod:`align.motion`), ``inf`` when not found, ``-1`` when its two depths sit on one side of the
    midpoint. The other position of the occluder (near in A when arriving: B sees it here; near in
    B when leaving) is the nearest hit breadth first over the rays (``rays``: :func:`step_tables`);
    the far-in-both surface is looked for along the opposite ray of that hit (the edge moved along
    it, so a narrow limb's far side does not pass for its trailing edge). A ray that leaves the
    image finds nothing further. One call for all pixels (a call per pixel costs more than its search)."""
    count, off, dist, ray, dyx, ray_dy, ray_dx, ray_d = rays
    H, W = A.shape
    n_rays, n_steps = ray_dy.shape
    Af, Bf = A.ravel(), B.ravel()
    da = np.full(idx.size, np.inf, np.float32)
    db = np.full(idx.size, np.inf, np.float32)
    for k in range(idx.size):
        p, mid = idx[k], mids[k]
        y, x = p // W, p % W
        if (Af[p] < mid) == (Bf[p] < mid):
            da[k] = db[k] = -1.0
            continue
        arriving = Bf[p] < mid
        inside = n_steps <= y < H - n_steps and n_steps <= x < W - n_steps
        C = Af if arriving else Bf
        d_near = np.float32(np.inf)
        r = -1
        for s in range(n_steps):
            for i in range(count[s]):
                if not inside and not (0 <= y + dyx[s, i, 0] < H and 0 <= x + dyx[s, i, 1] < W):
                    continue
                if C[p + off[s, i]] < mid:
                    d_near, r = dist[s, i], ray[s, i]
                    break
            if r >= 0:
                break
        d_far = np.float32(np.inf)
        opp = (r + n_rays // 2) % n_rays
        for s in range(n_steps if r >= 0 else 0):
            if not inside and not (0 <= y + ray_dy[opp, s] < H and 0 <= x + ray_dx[opp, s] < W):
                break
            q = p + ray_dy[opp, s] * W + ray_dx[opp, s]
            if not (Af[q] < mid) and not (Bf[q] < mid) and (Af[q] == Af[q] or Bf[q] == Bf[q]):
                d_far = ray_d[opp, s]
                break
        if arriving:
            da[k], db[k] = d_near, d_far
        else:
            da[k], db[k] = d_far, d_near
    return da, db


@numba.njit(cache=True, nogil=True)
def step_tables(ray_dy, ray_dx, ray_d, W):  # pragma: no cover - compiled
    """The search tables of :func:`rule_two` for an image ``W`` wide, from the rays (``(rays, steps)``
    each: offsets and distances, :func:`align.motion._offsets`): the rays step by step, nearest
    first (ties: by ray), so that the first hit of a step is its nearest, each pixel offset once
    (where two rays, or two steps, meet the same pixel, it is looked at the first time only: it
    cannot hold a hit the first look missed): ``(count, off, dist, ray, dyx, ray_dy, ray_dx,
    ray_d)``, ``count[s]`` entries of step ``s``, then each ``(steps, rays)``: flat offsets,
    distances, ray indices, ``(dy, dx)`` pairs; then the rays as given."""
    n_rays, n_steps = ray_dy.shape
    count = np.zeros(n_steps, np.int64)
    off = np.empty((n_steps, n_rays), np.int64)
    dist = np.empty((n_steps, n_rays), np.float32)
    ray = np.empty((n_steps, n_rays), np.int64)
    dyx = np.empty((n_steps, n_rays, 2), np.int64)
    for s in range(n_steps):
        order = np.argsort(ray_d[:, s], kind="mergesort")
        for r in order:
            o = ray_dy[r, s] * W + ray_dx[r, s]
            seen = False
            for t in range(s + 1):
                for i in range(count[t]):
                    seen = seen or off[t, i] == o
            if not seen:
                off[s, count[s]] = o
                dist[s, count[s]] = ray_d[r, s]
                ray[s, count[s]] = r
                dyx[s, count[s], 0] = ray_dy[r, s]
                dyx[s, count[s], 1] = ray_dx[r, s]
                count[s] += 1
    return count, off, dist, ray, dyx, ray_dy, ray_dx, ray_d
