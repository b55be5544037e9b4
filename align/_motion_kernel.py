"""The compiled search of :mod:`align.motion` (rule 2): for each pixel an edge crossed, the
distances to the two positions of that edge (imported on first use: numba takes a while to import)."""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def edge_distances(A, B, ys, xs, mids, dy, dx, dist, out_a, out_b):  # pragma: no cover - compiled
    """Per pixel ``k`` at ``(ys[k], xs[k])`` with midpoint depth ``mids[k]``: ``out_a[k], out_b[k]``,
    the distances (px, between pixel centres) to the edge's positions in the two frames (module
    docstring of :mod:`align.motion`), ``inf`` when not found within the offsets ``(dy, dx)``
    (sorted by ``dist``). A pixel whose two depths sit on one side of its midpoint gets ``-1``."""
    H, W = A.shape
    n_off = dy.size
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
        arriving = near_b
        d_ff = np.inf
        d_near = np.inf  # near in A (arriving) or near in B (leaving)
        for o in range(n_off):
            if d_ff < np.inf and d_near < np.inf:
                break
            qy = y + dy[o]
            qx = x + dx[o]
            if qy < 0 or qy >= H or qx < 0 or qx >= W:
                continue
            a = A[qy, qx]
            b = B[qy, qx]
            na = a < mid
            nb = b < mid
            if d_ff == np.inf and not na and not nb and (a == a or b == b):
                d_ff = dist[o]
            if d_near == np.inf and ((arriving and na) or (not arriving and nb)):
                d_near = dist[o]
        if arriving:
            out_a[k] = d_near
            out_b[k] = d_ff
        else:
            out_a[k] = d_ff
            out_b[k] = d_near
