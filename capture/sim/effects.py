"""Effects the simulator can switch on (``--effect NAME=VALUE``), and their validation.

Each effect acts on the rig's *target* sensor (``lq``; ``view0`` in ``multiview4-hq``,
``view1`` in ``multiview4``), except ``frame_drop_rate`` (every sensor) and
``hq_distortion_k1`` (the reference sensor's colour camera):

==================== =============== ==========================================================
name                 range           what it does
==================== =============== ==========================================================
clock_drift_ppm      [-1000, 1000]   the target's host clock runs fast (+) or slow (-) against
                                     the reference: ``Delta(t) = a + b (t - t0)``, b = ppm * 1e-6
depth_scale          [0.5, 2.0]      the target's depth is multiplied by the factor
depth_offset_mm      [-200, 200]     the target's depth gets this offset (after the scale):
                                     ``z' = s z + o``
distortion_k1        [-0.5, 0.5]     the target camera (depth and colour) has radial distortion
                                     k1 (OpenCV model); declared: its intrinsics carry it
hq_distortion_k1     [-0.5, 0.5]     the reference's colour camera has radial distortion k1
                                     (its depth camera has none); declared: its intrinsics carry it
rolling_shutter_ms   [0, 60]         the target's colour camera reads its rows out over this
                                     time (rolling shutter); its depth stays global-shutter
frame_drop_rate      [0, 0.9]        each frame of each sensor is dropped with this probability
frame_duplicate_rate [0, 0.5]        each frame of the target is, with this probability, a copy
                                     of its predecessor (same bytes, its own number and stamp)
==================== =============== ==========================================================

Rolling shutter convention: row ``y`` of an ``H``-row colour image is exposed at
``t + r ((y + 0.5) / H - 0.5)`` for a frame stamped at scene time ``t`` (the stamp is the
middle of the readout), ``r`` the readout time. The image is rendered in bands of rows, each at
its own instant, at most :data:`ROLLING_SHUTTER_BAND_MS` apart.

Declared effects appear in ``session.json`` under ``effects`` and in the fields they concern
(intrinsics ``coeffs``, ``clock_facts.drift_ppm``, per-stream ``dropped_frames``); with
``undeclared=True`` they are written to ``truth/truth.json`` only.

Example:
    >>> parse_effects(["depth_scale=1.02", "clock_drift_ppm=-50"])
    {'depth_scale': 1.02, 'clock_drift_ppm': -50.0}
    >>> SensorEffects.of({"depth_offset_mm": 20.0, "rolling_shutter_ms": 15.0})
    SensorEffects(depth_scale=1.0, depth_offset_m=0.02, readout_s=0.015)
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from capture.sim.errors import SimulationError

#: name -> (low, high, neutral value)
EFFECTS: dict[str, tuple[float, float, float]] = {
    "clock_drift_ppm": (-1000.0, 1000.0, 0.0),
    "depth_scale": (0.5, 2.0, 1.0),
    "depth_offset_mm": (-200.0, 200.0, 0.0),
    "distortion_k1": (-0.5, 0.5, 0.0),
    "hq_distortion_k1": (-0.5, 0.5, 0.0),
    "rolling_shutter_ms": (0.0, 60.0, 0.0),
    "frame_drop_rate": (0.0, 0.9, 0.0),
    "frame_duplicate_rate": (0.0, 0.5, 0.0),
}

#: largest time step between the row bands of a rolling-shutter image (ms)
ROLLING_SHUTTER_BAND_MS = 2.0


@dataclass(frozen=True)
class SensorEffects:
    """What the effects do to the frames of the target sensor: ``z' = depth_scale z + depth_offset_m``
    (metres), colour rows read out over ``readout_s`` seconds."""

    depth_scale: float = 1.0
    depth_offset_m: float = 0.0
    readout_s: float = 0.0

    @classmethod
    def of(cls, effects: dict[str, float]) -> "SensorEffects":
        return cls(float(effects.get("depth_scale", 1.0)), float(effects.get("depth_offset_mm", 0.0)) * 1e-3,
                   float(effects.get("rolling_shutter_ms", 0.0)) * 1e-3)

    @property
    def changes_depth(self) -> bool:
        return self.depth_scale != 1.0 or self.depth_offset_m != 0.0


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
