"""Clock drift: ``Delta(t) = a + b (t - t0)`` (the base model has ``b = 0``).

Signature: the time residual grows with time in the session; in pixels, the feature residual
is proportional to image velocity x time. Real consumer clocks drift tens to hundreds of ppm
(RealSense about 75 ppm): over a 30 s session 100 ppm is 3 ms.
"""
from __future__ import annotations

import numpy as np

from align.loop.effects.base import Effect


class ClockDrift(Effect):
    name = "clock_drift"
    params = ("b_ppm",)
    units = ("ppm",)
    steps = (0.5,)
    declared_as = ("clock_drift_ppm",)
    signature = "velocity_x_time"
    what = "the LQ clock runs at another rate than the HQ clock: Delta(t) = a + b (t - t0)"

    def time_offset_us(self, data, v: np.ndarray):
        return v[0] * 1e-6 * (data.t_hq_us - data.t0_us)

    def declared_values(self, declared: dict) -> np.ndarray | None:
        b = declared.get("clock_drift_ppm")
        return None if b is None else np.array([float(b)])
