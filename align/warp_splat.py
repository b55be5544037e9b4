"""What the warp's two splat engines share: the points to splat, the z-buffer's geometry and keys.

Pure numpy, no I/O. :class:`align.warp.DepthWarper` computes, per source point, the destination
position and inverse depth (steps 1-2 of the warp, see :mod:`align.warp`) and hands them to an
engine (:mod:`align.warp_numpy` or :mod:`align.warp_numba`), which does steps 3-5 (local plane,
splats, z-buffer) and returns the destination depth image.

Z-buffer key (int64, the maximum wins): its high int32 holds the top bits of ``w``'s float32
pattern (positive floats sort like their bit patterns), so the nearest surface wins to ~2 % of
``w``, then a fixed priority of the splat's offset; its low int32 holds ``w`` itself. Among splats
of one surface the choice thus depends on geometry only, not on the noisy values (keeping the
largest of several noisy ``w`` would bias the reference towards the camera). The empty key has
high half -1 (below every splat) and ``w`` = NaN, so ``1 / w`` is NaN where nothing landed.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

#: which int32 half of an int64 key holds ``w`` (low) and which the order (high)
LO_HALF, HI_HALF = (0, 1) if sys.byteorder == "little" else (1, 0)

#: the z-buffer's empty cell: high int32 -1 (below every splat), low int32 the bits of a float32 NaN
EMPTY_KEY = int(np.array([0x7FC00000, -1] if sys.byteorder == "little" else [-1, 0x7FC00000], np.int32).view(np.int64)[0])


def splat_offsets(k: int) -> list[tuple[int, int]]:
    """Splat offsets (a, b) from the pixel (floor u, floor v) for block size ``k``."""
    r = range(-(k // 2) + 1, k // 2 + 1 + (k % 2))
    return [(a, b) for b in r for a in r]


def splat_priorities(offsets) -> dict:
    """Fixed z-buffer priority of each splat offset among splats of one surface (first offset highest)."""
    return {o: len(offsets) - i for i, o in enumerate(offsets)}


def zkey(w: float, priority: int) -> tuple[int, int, int]:
    """The z-buffer order of one splat, as the engines' int64 key orders it."""
    bits = int(np.float32(w).view(np.int32))
    return (bits >> 18, priority, bits)


@dataclass(frozen=True)
class SplatGrid:
    """The destination side of the splat.

    Attributes:
        k: splat block size (destination pixels per side). r: padding of the z-buffer on every
        side (absorbs targets just outside the image). width, height: destination image, px.
        offsets: the ``k x k`` offsets :func:`splat_offsets` gives, in priority order.
        edge_reach: how far, in source-grid steps, a point's splat reaches towards a neighbour on
        another surface (see :mod:`align.warp`, step 4): 0.5 puts the edge at the midpoint, 0
        extrapolates nothing past the last sample; in ``[0, 1)``.
    """

    k: int
    r: int
    width: int
    height: int
    offsets: tuple
    edge_reach: float = 0.5

    @property
    def padded_width(self) -> int:
        return self.width + 2 * self.r

    @property
    def padded_height(self) -> int:
        return self.height + 2 * self.r

    @property
    def margin(self) -> int:
        """A point whose block can touch the image lies within this many pixels of it."""
        return self.k // 2 + 1

    def zbuffer_size(self) -> int:
        """Cells of one z-buffer: the padded image, a spare row pair and a trash cell."""
        return self.padded_height * self.padded_width + 2 * self.padded_width + 2 * self.k + 2

    def priorities(self) -> dict:
        return splat_priorities(self.offsets)

    def depth_from_keys(self, buf: np.ndarray) -> np.ndarray:
        """The destination depth ``(height, width)`` float32 metres from a filled z-buffer (NaN = empty)."""
        Wp = self.padded_width
        wv = buf[:self.padded_height * Wp].view(np.int32)[LO_HALF::2].view(np.float32)
        return np.divide(np.float32(1), wv).reshape(self.padded_height, Wp)[self.r:-self.r, self.r:-self.r]


#: the quadrants of a point's splat, as bits of :func:`diagonal_cuts`: (x side, y side) -> bit
QUADRANT_BITS = {(1, 1): 1, (-1, 1): 2, (1, -1): 4, (-1, -1): 8}


def diagonal_cuts(pts: "SourcePoints", sel: np.ndarray) -> np.ndarray:
    """Per selected point (flat indices ``sel``), the quadrants of its splat cut at the diagonal, as bits
    (:data:`QUADRANT_BITS`): both axis neighbours of the quadrant are linked to the point but the
    diagonal neighbour is linked to neither of them (another surface, or no sample). The point's splat
    there covers on its own only ``|sx| + |sy| < 1 + edge_reach`` (source-grid steps; step 4 of :mod:`align.warp`):
    the samples cover the triangle, not the square, so a surface ends at a diagonal silhouette instead
    of claiming the far surface's corner one pixel past it. ``(n,)`` int64."""
    W, cx, cy = pts.W, pts.cxp, pts.cyp
    sel = np.asarray(sel, np.int64)

    def t(a, idx):
        return np.take(a, idx, mode="clip") > 0   # out-of-grid indices occur only where a side link is 0

    cl, cr, cu, cd = cx[sel] > 0, cx[sel + 1] > 0, cy[sel] > 0, cy[sel + W] > 0
    q = ((cr & cd & ~(t(cy, sel + 1 + W) | t(cx, sel + W + 1))).astype(np.int64),
         (cl & cd & ~(t(cy, sel - 1 + W) | t(cx, sel + W))).astype(np.int64),
         (cr & cu & ~(t(cy, sel + 1) | t(cx, sel - W + 1))).astype(np.int64),
         (cl & cu & ~(t(cy, sel - 1) | t(cx, sel - W))).astype(np.int64))
    return q[0] | (q[1] << 1) | (q[2] << 2) | (q[3] << 3)


def merge_cut(buf: np.ndarray, cut: np.ndarray) -> None:
    """Add the splats of the quadrants cut at the diagonal (``cut``, keys like ``buf``) to the z-buffer ``buf``,
    in place, where another splat landed: there they take part in the z-test (a near surface still hides
    the far samples the source camera saw past its silhouette, within one grid step of it), but on their
    own they fill nothing (no sample covers that corner)."""
    np.maximum(buf, cut, out=buf, where=buf != EMPTY_KEY)


@dataclass
class SourcePoints:
    """Steps 1-2 of the warp for every point of the (cropped) source grid, flat, row-major.

    Attributes:
        u, v: destination pixel coordinates ``(N,)`` float32. w: inverse destination depth ``(N,)``
        1/m. valid: ``(N,)`` bool (depth present, in front of the destination camera).
        cxp: ``(N + 1,)`` float32 0/1, ``cxp[k]`` links pixels ``k - 1`` and ``k`` (same surface).
        cyp: ``(N + W,)`` float32 0/1, ``cyp[k]`` links pixels ``k - W`` and ``k``.
        W: width of the source grid (the y-neighbour of ``k`` is ``k + W``).
    """

    u: np.ndarray
    v: np.ndarray
    w: np.ndarray
    valid: np.ndarray
    cxp: np.ndarray
    cyp: np.ndarray
    W: int

    @property
    def N(self) -> int:
        return int(self.u.size)
