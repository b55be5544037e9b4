"""Rolling shutter of a colour camera: row ``y`` of an ``H``-row image is exposed at
``t + r ((y + 0.5) / H - 0.5)`` (``r`` the readout time; the stamp is the middle of the readout).

LQ camera: each track sample's instant moves by its row's offset (the interpolation then reads
the track at the right place). HQ camera: each feature's instant moves by its HQ row's offset.
Signature: feature residual proportional to image velocity x image row. Colour sensors read
out in 10-30 ms; the readout's range (:data:`MAX_READOUT_MS`) bounds the refit.

Without bounds the robust refit could run away: an LQ readout of seconds moves every track sample
out of its window, and a feature whose instant leaves its window has no residual, so the loss
falls as features drop out (rendered seed 14, 30 ms: the refit went to -2458 ms and the held-out
residual grew from 0.304 to 0.449 px).

Model error of the LQ readout (:data:`READOUT_MODEL_ERROR_MS`): on rendered sessions with 30 ms the
bounded refit reads +0.6, +1.1, -0.2 and +2.5 ms off (seeds 11-14) against deviations of
0.4-0.7 ms, an error all probes share; it is added in quadrature, as the HQ lens's ``k1`` one is.
"""
from __future__ import annotations

import numpy as np

from align.loop.effects.base import Effect

#: Largest readout time (ms) either sign: about two frame intervals at 30 fps (a negative readout is
#: a sensor read bottom to top). Real colour sensors read out in 10-30 ms.
MAX_READOUT_MS = 60.0

#: Error (ms) of the LQ readout estimate shared by all probes, solved from RMS(error /
#: sqrt(std^2 + m^2)) = 1 on rendered sessions, 30 ms, seeds 11-14 (1.28 ms; 2 of 4 intervals
#: covered without it). Held out: seeds 15-17 (notes of issue 12, session 6). None measured for the HQ.
READOUT_MODEL_ERROR_MS = 1.3


class RollingShutter(Effect):
    params = ("readout_ms",)
    units = ("ms",)
    steps = (0.05,)
    signature = "velocity_x_row"
    bounds = ((-MAX_READOUT_MS, MAX_READOUT_MS),)

    def __init__(self, camera: str) -> None:
        self.camera = camera
        self.name = f"rolling_shutter_{camera}"
        self.signature = "velocity_x_row" if camera == "lq" else "velocity_x_hq_row"
        self.declared_as = ("rolling_shutter_ms",) if camera == "lq" else ("hq_rolling_shutter_ms",)
        self.what = f"the {camera.upper()} colour camera exposes its rows one after another (readout time r)"
        self.model_error = (READOUT_MODEL_ERROR_MS,) if camera == "lq" else (0.0,)

    def time_offset_us(self, data, v: np.ndarray):
        if self.camera != "hq":
            return 0.0
        return v[0] * 1e3 * ((data.hq_xy[:, 1] + 0.5) / data.K_hq.height - 0.5)

    def sample_offset_us(self, data, stamps: np.ndarray, v: np.ndarray) -> np.ndarray:
        if self.camera != "lq":
            return stamps
        y = data.tracks[..., 1]
        off = np.where(np.isfinite(y), v[0] * 1e3 * ((y + 0.5) / data.K_lq.height - 0.5), 0.0)
        return stamps + off

    def declared_values(self, declared: dict) -> np.ndarray | None:
        r = declared.get(self.declared_as[0])
        return None if r is None else np.array([float(r)])
