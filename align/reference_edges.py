"""The warped reference's own error at depth edges, and the edge rule the aligned dataset uses.

Pure numpy/OpenCV, no I/O.

Model
-----
The HQ depth image is coarser than the LQ image it is warped onto (Kinect-class 512x424 at
``fx`` 365 px against 640x480 at ``fx`` 600 px: one HQ step is ~1.6 LQ pixels), and a
time-of-flight sensor mixes the two surfaces in the pixels along every depth edge (flying
pixels; the warp's continuity test drops them, see :mod:`align.warp`). Where a silhouette lies
between two HQ samples the reference cannot know where; whatever the warp guesses there is wrong
by the whole depth jump (0.3-3 m) for some pixels. Few pixels, but they dominate the reference's
RMSE: on a demo-like session (``perf/reference_error.py``) 0.73 % of the ROI is off by more than
50 mm, RMSE 77 mm beside MAE 6.8 mm. Traced, the large errors are of two kinds:

* **reference farther** (73 %): the far surface showing through the near one. The HQ camera sits
  12.5 cm beside the LQ camera, so on one side of every silhouette the LQ camera sees less of the
  background than the HQ camera does: far samples the HQ camera saw up to ~12 HQ pixels from the
  silhouette land, in the LQ image, just inside the near surface's true outline, and win wherever
  the near surface's samples were lost to mixing. They sit on the far side of a reference depth
  edge, within a pixel or two of it.
* **reference nearer** (27 %): on the other side (disocclusion) the near surface, extended half an
  HQ step past its last sample by the warp's midpoint rule, covers background the HQ camera never
  saw next to the near surface.

The rule (:class:`EdgeRule`, ``"strict"``): (1) no surface reaches past its last sample
(``edge_reach=0`` in :class:`align.warp.DepthWarper`), which removes the second kind; (2) the
pixels on the far side of a reference depth edge, within ``mask_px`` (3) of a surface at least
``edge_rel`` nearer, are masked (NaN), which removes most of the first. Every masked pixel is
counted and reported.

Measured on a demo-like session (``capture simulate --rig lq-hq --scene people --seconds 3
--seed 0``, scale 1, the smooth figures):

=====================================  ==============  ==============
HQ sensor against truth                midpoint        strict
=====================================  ==============  ==============
MAE / RMSE, leaderboard (90 frames)    6.32 / 69.6 mm  2.26 / 8.09 mm
pixels > 50 mm off, truth geometry     0.73 %          0.043 %
ROI pixels masked by the rule          0               2.9 %
ROI pixels without reference (all)     6.5 %           12.6 %
=====================================  ==============  ==============

(``perf/reference_error.py`` for rows 2-4, 6 pairs with truth's geometry; ``bench run`` for row 1.)
The cost is the masked band (2.9 % of the ROI) plus the gap no sample covers (3.2 %). What is
left (RMSE still 3.6x MAE) is the silhouette position inside one HQ step next to holes of the
reference (the large errors left lie within 2 px of a hole, 83 % with the reference nearer),
which no rule on the HQ depth alone can recover; masking the near side of such edges as well
bought RMSE 8.9 mm for another 2.8 % of the ROI and is not done. ``"midpoint"`` keeps the plain
warp: guess, mask nothing.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from align.errors import OptionError

#: the named rules: (edge reach of the warp, mask width in destination pixels)
RULES = {"strict": (0.0, 3), "midpoint": (0.5, 0)}


@dataclass(frozen=True)
class EdgeRule:
    """How the reference treats depth edges.

    Attributes:
        name: ``"strict"`` (the default of the aligned dataset) or ``"midpoint"`` (the plain warp).
        edge_reach: the warp's reach past a surface's last sample, source-grid steps, ``[0, 1)``.
        mask_px: far side of a reference edge masked within this many destination pixels (0: none).
        edge_rel: relative depth jump that makes an edge (0.03 = 3 %).
    """

    name: str = "strict"
    edge_reach: float = 0.0
    mask_px: int = 3
    edge_rel: float = 0.03

    @classmethod
    def named(cls, name: str, *, edge_rel: float = 0.03) -> "EdgeRule":
        if name not in RULES:
            raise OptionError(f"reference edge rule must be one of {', '.join(RULES)}, got {name!r}",
                              option="reference_edges")
        reach, mask_px = RULES[name]
        return cls(name=name, edge_reach=reach, mask_px=mask_px, edge_rel=edge_rel)

    def apply(self, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The reference ``(H, W)`` float32 metres with the rule's mask set to NaN, and the mask."""
        if self.mask_px <= 0:
            return reference, np.zeros(reference.shape, bool)
        mask = occluded_side(reference, radius_px=self.mask_px, edge_rel=self.edge_rel)
        return np.where(mask, np.float32(np.nan), reference).astype(np.float32, copy=False), mask

    def to_dict(self) -> dict:
        return {"rule": self.name, "edge_reach": self.edge_reach, "mask_px": self.mask_px, "edge_rel": self.edge_rel}


def occluded_side(depth: np.ndarray, *, radius_px: int = 2, edge_rel: float = 0.03) -> np.ndarray:
    """Pixels ``(H, W)`` bool with depth that lie within ``radius_px`` (a disc) of a pixel at least
    ``edge_rel`` of their depth nearer: the far side of every depth edge. NaN is no depth.

    Example:
        >>> z = np.full((1, 6), 2.0, np.float32); z[0, :2] = 1.0
        >>> occluded_side(z, radius_px=2).astype(int).tolist()
        [[0, 0, 1, 1, 0, 0]]
    """
    z = np.asarray(depth, np.float32)
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius_px + 1, 2 * radius_px + 1))
    nearest = cv2.erode(np.where(np.isfinite(z), z, np.inf).astype(np.float32), disc,
                        borderType=cv2.BORDER_CONSTANT, borderValue=np.inf)
    with np.errstate(invalid="ignore"):
        return np.isfinite(z) & (z - nearest > edge_rel * nearest)
