"""Dropped and duplicated frames in the time mapping.

* A *duplicated* frame carries the image of the frame before it under its own number and stamp
  (a driver re-sending its last buffer): its stamp is not the instant of its content, so it
  must neither be paired by its stamp nor sampled in a feature track. Found exactly: the stored
  image bytes (``sha256`` in the frame index) equal those of the previous frame of the stream,
  in both the depth and the colour stream. Sensor noise makes two genuine frames never equal
  bit for bit (an all-empty depth frame is not counted).
* A *dropped* frame leaves a gap in the frame numbers; the regularised time mapping
  (``align.timestamps``) honours it already. Reported as a rate with its binomial interval.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class FrameFindings:
    """Per stream: positions of duplicated frames, their count and the drop rate (gaps in numbers)."""

    duplicates: dict[str, np.ndarray]
    dropped: dict[str, int]
    expected: dict[str, int]

    def duplicate_positions(self, stream: str) -> np.ndarray:
        return self.duplicates.get(stream, np.zeros(0, np.int64))


def duplicated(frame_numbers: np.ndarray, sha_a, sha_b=None) -> np.ndarray:
    """Positions ``i > 0`` whose image hash equals position ``i - 1``'s (in both hash lists when two are given).

    ``sha_b`` is looked up by frame number (a colour stream may miss frames the depth has);
    without a ``sha_b`` entry for both frames only ``sha_a`` decides.
    """
    a = np.asarray(sha_a, dtype=object)
    same = np.zeros(a.size, bool)
    same[1:] = a[1:] == a[:-1]
    if sha_b is not None:
        fn = np.asarray(frame_numbers, np.int64)
        for i in np.flatnonzero(same):
            x, y = sha_b.get(int(fn[i])), sha_b.get(int(fn[i - 1]))
            if x is not None and y is not None and x != y:
                same[i] = False
    return np.flatnonzero(same)


def drop_interval(dropped: int, expected: int, *, z: float = 1.96) -> tuple[float, float, float]:
    """Drop rate and its Wilson score interval (95 %)."""
    if expected <= 0:
        return 0.0, 0.0, 1.0
    p = dropped / expected
    den = 1 + z * z / expected
    mid = (p + z * z / (2 * expected)) / den
    half = z * np.sqrt(p * (1 - p) / expected + z * z / (4 * expected * expected)) / den
    return float(p), float(max(0.0, mid - half)), float(min(1.0, mid + half))
