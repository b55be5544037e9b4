"""Effects the simulator can switch on (``--effect NAME=VALUE``), and their validation.

Each effect acts on the rig's *target* sensor (``lq``; ``view0`` in ``multiview4-hq``,
``view1`` in ``multiview4``), except ``frame_drop_rate``, which acts on every sensor:

================== =============== ==========================================================
name               range           what it does
================== =============== ==========================================================
clock_drift_ppm    [-1000, 1000]   the target's host clock runs fast (+) or slow (-) against
                                   the reference: ``Delta(t) = a + b (t - t0)``, b = ppm * 1e-6
depth_scale        [0.5, 2.0]      the target's depth is multiplied by the factor
distortion_k1      [-0.5, 0.5]     the target camera (depth and colour) has radial distortion
                                   k1 (OpenCV model); declared: its intrinsics carry it
frame_drop_rate    [0, 0.9]        each frame of each sensor is dropped with this probability
================== =============== ==========================================================

Declared effects appear in ``session.json`` under ``effects`` and in the fields they concern
(intrinsics ``coeffs``, ``clock_facts.drift_ppm``, per-stream ``dropped_frames``); with
``undeclared=True`` they are written to ``truth/truth.json`` only.

Example:
    >>> parse_effects(["depth_scale=1.02", "clock_drift_ppm=-50"])
    {'depth_scale': 1.02, 'clock_drift_ppm': -50.0}
"""
from __future__ import annotations

import math

from capture.sim.errors import SimulationError

#: name -> (low, high, neutral value)
EFFECTS: dict[str, tuple[float, float, float]] = {
    "clock_drift_ppm": (-1000.0, 1000.0, 0.0),
    "depth_scale": (0.5, 2.0, 1.0),
    "distortion_k1": (-0.5, 0.5, 0.0),
    "frame_drop_rate": (0.0, 0.9, 0.0),
}


def parse_effects(effects) -> dict[str, float]:
    """``["NAME=VALUE", ...]`` or ``{NAME: VALUE}`` to a checked ``{NAME: float}``."""
    if effects is None:
        return {}
    items = effects.items() if isinstance(effects, dict) else (_split(e) for e in effects)
    out: dict[str, float] = {}
    for name, raw in items:
        if name not in EFFECTS:
            raise SimulationError(f"--effect {name}: unknown effect (known: {', '.join(EFFECTS)})")
        if name in out:
            raise SimulationError(f"--effect {name}: given more than once")
        try:
            value = float(raw)
        except (TypeError, ValueError):
            raise SimulationError(f"--effect {name}={raw}: value is not a number") from None
        lo, hi, _ = EFFECTS[name]
        if not math.isfinite(value) or not lo <= value <= hi:
            raise SimulationError(f"--effect {name}={raw}: value must be within [{lo:g}, {hi:g}]")
        out[name] = value
    return out


def _split(item: str) -> tuple[str, str]:
    name, sep, value = str(item).partition("=")
    if not sep or not name.strip() or not value.strip():
        raise SimulationError(f"--effect {item!r}: expected NAME=VALUE, e.g. depth_scale=1.02")
    return name.strip(), value.strip()
