"""Reader of a simulated session's ``truth/`` folder (scoring and tests only; alignment never reads it).

``read_truth(session_root) -> Truth``. Layout and fields: ``data_manifests/truth.md``.

Example (on a simulated session ``sim``)::

    t = read_truth("sim")
    t.time_shift_us, t.T_lq_hq            # the answers alignment must find
    z = t.depth("lq", frame_number)       # float32 metres, NaN = no surface
    t.scene_time_us("lq", frame_number)   # int64 µs
    t.T_world("hq", "color")              # Transform, the HQ colour camera's pose
"""
from __future__ import annotations

import csv
import io
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from capture.camera import Intrinsics, Transform
from capture.errors import CalibrationError, SessionFormatError
from data_manifests import schema_problem
from depthbench import frames as codec
from depthbench.fsutil import read_json, safe_join

TRUTH_FORMAT = "depthbench.truth"
TRUTH_COLUMNS = ("frame_number", "scene_time_us", "device_timestamp_us", "host_timestamp_us", "host_jitter_us",
                 "file", "sha256")


@dataclass
class Truth:
    """The ground truth of a simulated session.

    Attributes:
        root: the ``truth/`` folder. info: the parsed ``truth.json``.
        time_shift_us: SSDD's Delta: an instant the reference (HQ) host clock stamps t is stamped
            t + Delta by the target (LQ) host clock (at t = t0 when the clock drifts).
        T_lq_hq: maps points of the reference (HQ) depth camera into the target (LQ) depth camera.
        reference, target: sensor ids (``hq``/``lq`` for the lq-hq rig).
    """

    root: Path
    info: dict
    frames_tables: dict[str, pd.DataFrame]

    @property
    def time_shift_us(self) -> int:
        return int(self.info["time_shift_us"])

    @property
    def T_lq_hq(self) -> Transform:
        return Transform.from_list(self.info["T_lq_hq"])

    @property
    def reference(self) -> str:
        return self.info["reference_sensor"]

    @property
    def target(self) -> str:
        return self.info["target_sensor"]

    @property
    def effects(self) -> dict[str, float]:
        return dict(self.info["effects"])

    @property
    def sensors(self) -> list[str]:
        return list(self.info["sensors"])

    def time_shift_at_us(self, t_reference_us) -> np.ndarray:
        """Delta(t) = a + b (t - t0) at reference host time(s) ``t_reference_us`` (float µs)."""
        m = self.info["time_shift_model"]
        return m["a_us"] + m["b"] * (np.asarray(t_reference_us, dtype=np.float64) - m["t0_us"])

    def clock(self, sensor: str) -> dict:
        """The true clock parameters of ``sensor`` (see ``capture.sim.clocks``)."""
        return dict(self._sensor_key(self.info["clocks"], sensor))

    def frames(self, sensor: str) -> pd.DataFrame:
        """``truth/<sensor>/frames.csv``: frame_number, scene_time_us, device/host timestamps, jitter, file, sha256."""
        return self._sensor_key(self.frames_tables, sensor)

    def scene_time_us(self, sensor: str, frame_number: int) -> int:
        return int(self._row(sensor, frame_number)["scene_time_us"])

    def depth(self, sensor: str, frame_number: int, *, verify: bool = True) -> np.ndarray:
        """Noise-free depth ``(H, W)`` float32 metres (NaN = no surface), pixel for pixel the
        sensor's depth image as rendered (lens distortion included)."""
        row = self._row(sensor, frame_number)
        table = self.root / sensor / "frames.csv"
        path = safe_join(self.root, row["file"], source=table, error=SessionFormatError)
        data = codec.read_frame_bytes(path, sha256=row["sha256"] if verify else None, table=table,
                                      what="truth depth file", error=SessionFormatError)
        return codec.decode_depth_png(data, unit_m=float(self.info["truth_depth_unit_m"]), where=path,
                                      error=SessionFormatError)

    def T_world(self, sensor: str, camera: str = "depth") -> Transform:
        """Pose ``T_world_cam`` of ``sensor``'s ``depth`` or ``color`` camera."""
        return Transform.from_list(self._sensor_key(self.info["sensors"], sensor)[f"T_world_{camera}"])

    def intrinsics(self, sensor: str, camera: str = "depth") -> Intrinsics:
        """Intrinsics as rendered (with any lens distortion, declared or not)."""
        return Intrinsics.from_dict(self._sensor_key(self.info["sensors"], sensor)[f"{camera}_intrinsics"])

    def T_dst_src(self, dst: str, src: str) -> Transform:
        """Maps points of ``src``'s depth camera into ``dst``'s depth camera."""
        return self.T_world(dst).inverse() @ self.T_world(src)

    def _sensor_key(self, d: dict, sensor: str):
        try:
            return d[sensor]
        except KeyError:
            raise SessionFormatError(f"{self.root / 'truth.json'}: no sensor {sensor!r} in the truth") from None

    def _row(self, sensor: str, frame_number: int) -> pd.Series:
        df = self.frames(sensor)
        hit = np.flatnonzero(df["frame_number"].to_numpy() == int(frame_number))
        if hit.size == 0:
            raise SessionFormatError(f"{self.root / sensor / 'frames.csv'}: no frame {frame_number}")
        return df.iloc[hit[0]]


def read_truth(session_root: str | os.PathLike) -> Truth:
    """Open ``SESSION/truth/``: parse ``truth.json`` and every ``<sensor>/frames.csv``.

    Raises :class:`SessionFormatError` naming the file and the problem (missing truth, bad JSON,
    missing field, bad table)."""
    root = Path(session_root) / "truth"
    path = root / "truth.json"
    info = read_json(path, error=SessionFormatError, missing=" (not a simulated session with ground truth)")
    _check_info(info, path)
    tables = {}
    for sensor, s in info["sensors"].items():
        table = safe_join(root, s.get("frames", f"{sensor}/frames.csv"), source=path, error=SessionFormatError)
        tables[sensor] = _read_table(table)
    return Truth(root, info, tables)


def _check_info(info, path: Path) -> None:
    if not isinstance(info, dict) or info.get("format") != TRUTH_FORMAT:
        raise SessionFormatError(f"{path}: 'format' must be {TRUTH_FORMAT!r}")
    if str(info.get("format_version", "")).split(".")[0] != "1":
        raise SessionFormatError(f"{path}: unknown format version {info.get('format_version')!r}")
    problem = schema_problem("truth", info)
    if problem:
        raise SessionFormatError(f"{path}: {problem}")
    try:
        Transform.from_list(info["T_lq_hq"])
    except CalibrationError as exc:
        raise SessionFormatError(f"{path}: T_lq_hq: {exc}") from None


def _read_table(path: Path) -> pd.DataFrame:
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise SessionFormatError(f"{path}: truth frames table is missing") from None
    rows = list(csv.reader(io.StringIO(text)))
    if not rows or tuple(rows[0]) != TRUTH_COLUMNS:
        raise SessionFormatError(f"{path}: header must be {','.join(TRUTH_COLUMNS)}")
    df = pd.DataFrame(rows[1:], columns=list(TRUTH_COLUMNS))
    try:
        for col in TRUTH_COLUMNS[:5]:
            df[col] = df[col].astype(np.int64)
    except ValueError as exc:
        raise SessionFormatError(f"{path}: a number column holds a non-integer ({exc})") from None
    return df
