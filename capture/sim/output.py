"""What a simulated session declares (``session.json``) and what only ``truth/`` knows.

Builds the manifest handed to :class:`capture.session.SessionWriter` and writes ``truth/``
(documented in ``data_manifests/truth.md``). The split is the point of the simulator:
undeclared effects, the true time shift and the true extrinsics between LQ and HQ appear in
``truth/`` only.
"""
from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from capture.camera import Intrinsics
from capture.sim.clocks import Clock, Schedule
from capture.sim.rigs import Rig, SensorSpec
from depthbench.fsutil import atomic_write_bytes, atomic_write_json, atomic_write_text

TRUTH_FORMAT = "depthbench.truth"
TRUTH_FORMAT_VERSION = "1.0"
#: Truth depth PNGs are uint16 in units of 0.1 mm (0 = no surface; max 6.5535 m).
TRUTH_DEPTH_UNIT_M = 0.0001
TRUTH_COLUMNS = ("frame_number", "scene_time_us", "device_timestamp_us", "host_timestamp_us", "host_jitter_us",
                 "file", "sha256")


@dataclass
class Plan:
    """Everything decided before the first frame is rendered."""

    rig: Rig                      # as rendered (effects applied)
    scene_name: str
    seed: int
    seconds: float
    static: bool
    scale: float
    effects: dict[str, float]
    declared: bool
    clocks: dict[str, Clock]
    schedules: dict[str, Schedule]
    color_encoding: str = "auto"
    name: str = ""

    def color_encoding_of(self, sensor: str) -> str:
        """``auto``: PNG for the LQ/view sensors, JPEG for the HQ (Azure Kinect records MJPEG colour)."""
        if self.color_encoding != "auto":
            return self.color_encoding
        return "jpeg" if self.rig.sensor(sensor).role == "hq" else "png"

    @property
    def time_shift_us(self) -> int:
        r, t = self.rig.reference, self.rig.target
        return int(self.clocks[t].host_offset_us - self.clocks[r].host_offset_us)


# ----------------------------------------------------------------------------- session.json
def declared_intrinsics(plan: Plan, spec: SensorSpec, K: Intrinsics) -> Intrinsics:
    """Intrinsics as the session states them: an undeclared lens distortion is left out."""
    return K if plan.declared else K.without_distortion()


def _stream(plan: Plan, spec: SensorSpec, kind: str) -> dict:
    K = declared_intrinsics(plan, spec, spec.depth if kind == "depth" else spec.color)
    d = {"type": kind, "width": K.width, "height": K.height, "fps": spec.fps,
         "encoding": "png16" if kind == "depth" else plan.color_encoding_of(spec.id), "intrinsics": K.to_dict(),
         "dropped_frames": int(len(plan.schedules[spec.id].dropped_frame_numbers))}
    if kind == "depth":
        d["depth_unit_m"] = spec.depth_unit_m
    return d


def _sensor(plan: Plan, spec: SensorSpec) -> dict:
    return {
        "role": spec.role, "model": spec.model, "serial": spec.serial or f"SIM-{spec.id.upper()}",
        "technology": spec.technology,
        "streams": {"depth": _stream(plan, spec, "depth"), "color": _stream(plan, spec, "color")},
        "T_depth_color": spec.T_depth_color.to_list(),
        "clock": {"device_timestamp": "the sensor's own oscillator at exposure (its own time domain)",
                  "host_timestamp": "arrival at the recording computer (the time base alignment uses)",
                  "hardware_sync": False},
        "noise": spec.noise_dict(),
    }


def session_manifest(plan: Plan) -> dict:
    """The ``session.json`` content (without checksums and status, which the writer adds)."""
    t0 = plan.clocks[plan.rig.reference].host_offset_us
    manifest = {
        "name": plan.name,
        "created_utc": datetime.fromtimestamp(t0 // 10**6, timezone.utc).isoformat(timespec="seconds"),
        "time_base": "host",
        "source": {"kind": "simulator", "program": "depthbench capture simulate", "rig": plan.rig.name,
                   "scene": plan.scene_name, "seed": plan.seed, "seconds": plan.seconds, "static": plan.static,
                   "scale": plan.scale, "truth": "truth/truth.json (scoring and tests only)"},
        "sensors": {s.id: _sensor(plan, s) for s in plan.rig.sensors},
        "extrinsics": [{"dst": dst, "src": src, "T": plan.rig.T_dst_src(dst, src).to_list(), "source": "calibrated"}
                       for dst, src in plan.rig.declared_extrinsics],
        "clock_facts": {"hardware_sync": False},
        "effects": dict(plan.effects) if plan.declared else {},
    }
    if plan.declared and "clock_drift_ppm" in plan.effects:
        manifest["clock_facts"]["drift_ppm"] = plan.effects["clock_drift_ppm"]
    return manifest


# ----------------------------------------------------------------------------- truth/
def truth_manifest(plan: Plan) -> dict:
    """The ``truth/truth.json`` content."""
    rig, ref, tgt = plan.rig, plan.rig.reference, plan.rig.target
    t0 = plan.clocks[ref].host_offset_us
    pairs = {}
    for s in rig.sensors:
        if s.id == ref:
            continue
        c = plan.clocks[s.id]
        pairs[s.id] = {"time_shift_us": int(c.host_offset_us - t0), "drift_ppm": c.host_drift_ppm,
                       "T_sensor_reference": rig.T_dst_src(s.id, ref).to_list()}
    drift = plan.clocks[tgt].host_drift_ppm
    return {
        "format": TRUTH_FORMAT, "format_version": TRUTH_FORMAT_VERSION,
        "rig": rig.name, "scene": plan.scene_name, "seed": plan.seed, "seconds": plan.seconds,
        "static": plan.static, "scale": plan.scale, "time_base": "host",
        "reference_sensor": ref, "target_sensor": tgt,
        "time_shift_us": plan.time_shift_us,
        "time_shift_model": {"a_us": plan.time_shift_us, "b": drift * 1e-6, "t0_us": int(t0),
                             "definition": "an instant stamped t by the reference sensor's host clock is stamped "
                                           "t + a_us + b * (t - t0_us) by the target sensor's host clock"},
        "drift_ppm": drift,
        "T_lq_hq": rig.T_dst_src(tgt, ref).to_list(),
        "pairs": pairs,
        "effects": dict(plan.effects), "effects_declared": bool(plan.declared), "effect_target": tgt,
        "truth_depth_unit_m": TRUTH_DEPTH_UNIT_M,
        "clocks": {sid: c.to_dict() | {"dropped_frame_numbers": plan.schedules[sid].dropped_frame_numbers.tolist()}
                   for sid, c in plan.clocks.items()},
        "sensors": {s.id: _truth_sensor(s) for s in rig.sensors},
    }


def _truth_sensor(s: SensorSpec) -> dict:
    return {"role": s.role, "technology": s.technology,
            "T_world_depth": s.T_world_depth.to_list(), "T_world_color": s.T_world_color.to_list(),
            "T_depth_color": s.T_depth_color.to_list(),
            "depth_intrinsics": s.depth.to_dict(), "color_intrinsics": s.color.to_dict(),
            "depth_unit_m": s.depth_unit_m, "noise": s.noise_dict(),
            "frames": f"{s.id}/frames.csv"}


class TruthWriter:
    """Writes ``truth/<sensor>/depth/<n>.png`` per frame, then the tables and ``truth.json``."""

    def __init__(self, session_root: Path, plan: Plan) -> None:
        self.root = Path(session_root) / "truth"
        self.plan = plan
        self.rows: dict[str, list[tuple]] = {s.id: [] for s in plan.rig.sensors}
        for s in plan.rig.sensors:
            (self.root / s.id / "depth").mkdir(parents=True, exist_ok=True)

    def add(self, sensor: str, i: int, png: bytes, sha256: str) -> None:
        """Record frame ``i`` of ``sensor``'s schedule with its noise-free depth as an encoded
        uint16 PNG in :data:`TRUTH_DEPTH_UNIT_M` units (and the PNG's sha256)."""
        s = self.plan.schedules[sensor]
        fn = int(s.frame_number[i])
        rel = f"{sensor}/depth/{fn:08d}.png"
        atomic_write_bytes(self.root / rel, png)
        self.rows[sensor].append((fn, int(s.scene_time_us[i]), int(s.device_timestamp_us[i]),
                                  int(s.host_timestamp_us[i]), int(s.host_jitter_us[i]), rel, sha256))

    def close(self) -> None:
        for sensor, rows in self.rows.items():
            buf = io.StringIO()
            w = csv.writer(buf, lineterminator="\n")
            w.writerow(TRUTH_COLUMNS)
            w.writerows(rows)
            atomic_write_text(self.root / sensor / "frames.csv", buf.getvalue())
        atomic_write_json(self.root / "truth.json", truth_manifest(self.plan))
