"""Clock drift: ``Delta(t) = a + b (t - t0)`` (the base model has ``b = 0``).

Signature: the time residual grows with time in the session; in pixels, the feature residual
is proportional to image velocity x time. Real consumer clocks drift tens to hundreds of ppm
(RealSense about 75 ppm): over a 30 s session 100 ppm is 3 ms.

Model error of ``b``: the regularised (dejittered) stamps of the two streams are off the true
instants by an amount that wanders over a session (RMS about 100 µs against the simulator's
jitter-free stamps: notes of issue 12, session 4), which tilts the fitted rate by about
``WANDER_US sqrt(12) / span`` for probes spread over ``span`` seconds, a shared error the
cluster-robust deviation cannot see. It is added in quadrature (:meth:`ClockDrift.model_errors`).
On rendered 8 s sessions with 1000 ppm (seeds 11-12) the errors, -51 and -67 ppm against fitted
deviations of 42 and 30 ppm, give 103 µs for the same wander when solved for RMS error/std = 1.

Detection limit of short sessions (issue 12, session 7). On rendered people sessions (scale 0.5)
1000 ppm is found over 8 s (4 of 4 seeds; 500 ppm 5 of 6) and only on 1 of 8 seeds over 4 s. The
drift reaches the loop in full: a drift session and the clean session of the same seed have
byte-identical images and probes and differ only in the LQ stamps (which follow the simulator's clock
formulas after dejittering, ``tests/align/test_timestamps.py``), and the joint fit of pose, shift and
drift reads the clean session's own drift plus 999 and 1000 ppm (seeds 11, 12). Over 4 s the clean
sessions' own drift is biased and noisy: -204 ppm mean, 116 ppm sd over seeds 11-18 (8 s: -11 and
51 ppm, seeds 11-14). The figures carry few and slow features (2-44 of about 130 per probe,
0.05-0.26 px/ms), and over 4 s ``b`` correlates with the pose (0.6-0.7 with its x translation): the
moving features move the fitted pose 0.4-1.7 mm in x from where the static ones put it, and the drift
fitted with it reads 240 ppm lower on average than at the static features' pose (there: +26 ppm).
Per-probe shifts read at the base fit's pose show only half a drift (session 6's ~470 ppm): that pose,
fitted with a constant shift, absorbs half of it through the same correlation; the loop refits the
pose with the drift and does not lose it.
"""
from __future__ import annotations

import numpy as np

from align.loop.effects.base import Effect

#: RMS wander (µs) over a session of the stamps' error (see the module docstring).
WANDER_US = 100.0


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

    def model_errors(self, data) -> tuple[float, ...]:
        """``(b_ppm,)``: :data:`WANDER_US` spread as a trend over the probes' span."""
        t = np.asarray(data.t_hq_us, np.float64)
        span_s = float(t.max() - t.min()) * 1e-6 if t.size else 0.0
        return (WANDER_US * np.sqrt(12.0) / span_s,) if span_s > 0 else (0.0,)

    def declared_values(self, declared: dict) -> np.ndarray | None:
        b = declared.get("clock_drift_ppm")
        return None if b is None else np.array([float(b)])
