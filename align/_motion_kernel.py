"""The compiled search of :mod:`align.motion` (rule 2): for each pixel an edge crossed, the
distances to the two positions of that edge, along the direction it moved (imported on first use:
numba takes a while to import)."""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def edge_distances(A, B, ys, xs, mids, ray_dy, ray_dx, ray_d, out_a, out_b):  # pragma: no cover - compiled
    """Per pixel ``k`` at ``(ys[k], xs[k])`` with midpoint depth ``mids[k]``: ``out_a[k], out_b[k]``,
    the distances (px, between pixel centres) to the edge's positions in frames A and B (module
    docstring of :mod:`align.motion`), ``inf`` when not found. The other position of the occluder
    (near in A for an arriving one, near in B for a leaving one) is looked for along every ray
    ``(ray_dy[r], ray_dx[r])`` (distances ``ray_d[r]``, increasing); the far-in-both surface along the
    opposite ray of the nearest hit. A pixel whose two depths sit on one side of its midpoint gets ``-1``."""
    H, W = A.shape
    n_rays, n_steps = ray_dy.shape
    live = np.empty(n_rays, np.bool_)
    for k in range(ys.size):
        y, x, mid = ys[k], xs[k], mids[k]
        near_a = A[y, x] < mid
        near_b = B[y, x] < mid
        out_a[k] = np.inf
        out_b[k] = np.inf
        if near_a == near_b:
            out_a[k] = -1.0
            out_b[k] = -1.0
            continue
        arriving = near_b  # the occluder is where B saw it; where A saw it is the other position
        best = np.inf
        best_r = -1
        for r in range(n_rays):
            live[r] = True
        for s in range(n_steps):  # breadth first: every ray one step further, stop at the first hit
            for r in range(n_rays):
                if not live[r]:
                    continue
                qy = y + ray_dy[r, s]
                qx = x + ray_dx[r, s]
                if qy < 0 or qy >= H or qx < 0 or qx >= W:
                    live[r] = False
                    continue
                if ((A[qy, qx] < mid) if arriving else (B[qy, qx] < mid)) and ray_d[r, s] < best:
                    best = ray_d[r, s]
                    best_r = r
            if best_r >= 0:
                break
        if best_r < 0:
            continue
        d_ff = np.inf
        opp = (best_r + n_rays // 2) % n_rays  # the edge moved along the nearest hit's ray
        for s in range(n_steps):
            qy = y + ray_dy[opp, s]
            qx = x + ray_dx[opp, s]
            if qy < 0 or qy >= H or qx < 0 or qx >= W:
                break
            a = A[qy, qx]
            b = B[qy, qx]
            if not (a < mid) and not (b < mid) and (a == a or b == b):
                d_ff = ray_d[opp, s]
                break
        if arriving:
            out_a[k] = best
            out_b[k] = d_ff
        else:
            out_a[k] = d_ff
            out_b[k] = best
