"""The identity method: the LQ depth as the sensor gave it (every leaderboard's first column)."""
from __future__ import annotations

from methods.base import Denoiser


class Raw(Denoiser):
    """The identity: the LQ depth as the sensor gave it."""

    name = "raw"
    description = "identity (the sensor's depth)"

    def _denoise(self, depth, color, camera):
        return depth.copy()
