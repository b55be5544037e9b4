"""What :func:`bench.diagnose.diagnose` reads: the frames of one sensor with a reference.

Pure dataclasses (no I/O); :mod:`bench.diagnose.sources` fills them from session folders,
aligned datasets and the real captures.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from capture.camera import Intrinsics

#: reference kinds: ``truth`` (simulator), ``fused`` (a better sensor / multi-frame fusion),
#: ``board`` (plane fitted to the depth inside a detected ChArUco board), ``planes`` (local planes)
INDEPENDENT_REFERENCES = ("truth", "fused")


@dataclass
class BoardView:
    """A ChArUco board seen by the colour camera registered with the depth: the board plane
    ``n . p = d_units`` in *square units* (the board's size is not always known), the pixel mask
    of the board, the corners used and the pose's reprojection RMS (px); optionally the corners
    ``(N, 2)`` px and their board coordinates ``(N, 3)`` in square units (for the lens check)."""

    n: np.ndarray
    d_units: float
    mask: np.ndarray
    n_corners: int
    rms_px: float
    corners_px: np.ndarray | None = None
    corners_board: np.ndarray | None = None


@dataclass
class SensorFrames:
    """Frames of one sensor. Depths ``(H, W)`` float32 metres, NaN = none; ``reference[i]`` the
    reference depth of frame ``i`` (NaN where none; None: build local planes); ``luminance[i]``
    ``(H, W)`` float32 in [0, 1] of the registered colour image, or None; ``group[i]``: frames
    with the same group number film the same static view (temporal noise)."""

    sensor: str
    model: str
    technology: str
    intrinsics: Intrinsics
    depth: list[np.ndarray]
    reference: list[np.ndarray | None]
    reference_kind: str
    luminance: list[np.ndarray | None] = field(default_factory=list)
    group: list[int] = field(default_factory=list)
    board: list[BoardView | None] = field(default_factory=list)
    stereo_focal_px: float | None = None
    baseline_m: float | None = None
    depth_unit_m: float = 0.001
    source: str = ""
    notes: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        n = len(self.depth)
        self.luminance = self.luminance or [None] * n
        self.group = self.group or list(range(n))
        self.board = self.board or [None] * n

    @property
    def fB(self) -> float | None:
        """Focal length (px, at the matcher's resolution) times baseline (m) of a stereo sensor."""
        if self.stereo_focal_px and self.baseline_m:
            return float(self.stereo_focal_px * self.baseline_m)
        return None

    @property
    def independent_reference(self) -> bool:
        return self.reference_kind in INDEPENDENT_REFERENCES
