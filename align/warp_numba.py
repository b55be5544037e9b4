"""The warp's compiled engine: steps 3-5 (local plane, splats, z-buffer) as one loop over the points.

numba; the same rules, the same float32 arithmetic order and the same int64 keys as the numpy
engine (:mod:`align.warp_numpy`; the tests check both against each other and against the
per-pixel reference :func:`align.warp_reference.warp_depth_loop`). The scatter with a z-test is
a loop by nature: numpy can only do it with gathers and ``ufunc.at``, which cost more than the
rest of the warp together. The loop lives in :mod:`align._warp_kernel`.
"""
from __future__ import annotations

import numpy as np

from align.warp_splat import EMPTY_KEY, SourcePoints, SplatGrid, merge_cut

_KERNEL: list = []


def have_numba() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:  # pragma: no cover - numba is a dependency
        return False
    return True


def splat_numba(pts: SourcePoints, grid: SplatGrid, buf: np.ndarray) -> np.ndarray:
    """Steps 3-5 for every valid point; ``buf`` is the z-buffer scratch (int64, two of
    :meth:`SplatGrid.zbuffer_size`).

    Returns the destination depth ``(height, width)`` float32 metres, NaN where nothing landed.
    """
    buf.fill(EMPTY_KEY)
    n = grid.zbuffer_size()
    main, cut = buf[:n], buf[n:2 * n]   # the z-buffer and the splats of quadrants cut at the diagonal
    prio = grid.priorities()
    offs = (np.array([o[0] for o in grid.offsets], np.int64), np.array([o[1] for o in grid.offsets], np.int64),
            np.array([prio[o] for o in grid.offsets], np.int64))
    geom = (np.int64(pts.W), np.float32(grid.width), np.float32(grid.height), np.float32(grid.margin),
            np.float32(2 * (grid.k // 2)), np.int64(grid.padded_width), np.int64(grid.r), np.float32(grid.edge_reach))
    _kernels()(main, cut, pts.u, pts.v, pts.w, pts.cxp, pts.cyp, pts.valid, geom, offs)
    merge_cut(main, cut)
    return grid.depth_from_keys(main)


def _kernels():
    """The point loop, compiled on first use (cached on disk)."""
    if not _KERNEL:
        from align._warp_kernel import kernel

        _KERNEL.append(kernel)
    return _KERNEL[0]
