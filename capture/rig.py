"""Rig files (TOML): which sensors to record, with which driver, streams and sync settings.

The format is documented in ``data_manifests/rig.md``; examples are in ``data_manifests/rigs/``.
:func:`load_rig` reads and checks a file; :func:`parse_rig` checks an already parsed dict.
Every problem is a :class:`RigError` of one line naming the file, the sensor and the field.
This module checks the shape of the file and that each driver name is known; it does not
import driver SDKs (the recorder asks each driver's ``check_config`` when it opens the rig).
"""
from __future__ import annotations

import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from capture.camera import Transform
from capture.drivers.base import ENCODINGS, STREAM_TYPES, SensorConfig, StreamSettings, known_drivers
from capture.errors import CalibrationError, RigError

ROLES = ("lq", "hq", "view")
ID_PATTERN = re.compile(r"^[a-z0-9_]{1,32}$")
_TOP_KEYS = {"name", "description", "time_base", "sensor", "extrinsics", "clock_facts"}
_SENSOR_KEYS = {"id", "role", "driver", "serial", "model", "streams", "sync", "options"}
_STREAM_KEYS = {"type", "width", "height", "fps", "encoding"}
_EXTRINSIC_KEYS = {"dst", "src", "T", "source"}
_CLOCK_KEYS = {"time_shift_us", "drift_ppm", "hardware_sync"}
#: options whose value is a path, resolved against the rig file's folder.
PATH_OPTIONS = ("session", "file")


@dataclass(frozen=True)
class Rig:
    """A parsed rig file.

    Attributes:
        name: session name to record under (default: the file's stem).
        sensors: sensor configs in file order.
        time_base: ``"host"`` or ``"device"`` (written to ``session.json``).
        extrinsics: declared transforms ``{"dst", "src", "T" (4x4 list), "source"}`` copied to the session.
        clock_facts: declared clock facts copied to the session.
        path: the file it came from (None when built in code).
    """

    name: str
    sensors: tuple[SensorConfig, ...]
    time_base: str = "host"
    extrinsics: tuple[dict, ...] = ()
    clock_facts: dict = field(default_factory=dict)
    description: str = ""
    path: Path | None = None

    def sensor(self, sensor_id: str) -> SensorConfig:
        for s in self.sensors:
            if s.id == sensor_id:
                return s
        raise RigError(f"{self.path or 'rig'}: no sensor {sensor_id!r} (sensors: {', '.join(s.id for s in self.sensors)})")


def load_rig(path: str | os.PathLike) -> Rig:
    """Read and check a rig TOML file (relative option paths resolve against its folder)."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise RigError(f"{path}: rig file not found") from None
    except IsADirectoryError:
        raise RigError(f"{path}: is a folder, not a rig file") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise RigError(f"{path}: not valid TOML ({exc})") from None
    return parse_rig(data, where=path, base_dir=path.parent, default_name=path.stem)


def parse_rig(data: dict, *, where: str | os.PathLike = "rig", base_dir: str | os.PathLike | None = None,
              default_name: str = "rig") -> Rig:
    """Check a parsed rig dict and build a :class:`Rig`."""
    _no_unknown(data, _TOP_KEYS, f"{where}")
    sensors_raw = data.get("sensor")
    if not isinstance(sensors_raw, list) or not sensors_raw:
        raise RigError(f"{where}: no sensors (add at least one [[sensor]] table)")
    sensors = tuple(_sensor(s, i, where, base_dir) for i, s in enumerate(sensors_raw, start=1))
    seen: set[str] = set()
    for s in sensors:
        if s.id in seen:
            raise RigError(f"{where}: sensor id {s.id!r} is used twice")
        seen.add(s.id)
    time_base = data.get("time_base", "host")
    if time_base not in ("host", "device"):
        raise RigError(f"{where}: time_base must be 'host' or 'device', got {time_base!r}")
    name = data.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise RigError(f"{where}: name must be a non-empty string")
    extrinsics = tuple(_extrinsic(e, i, where, seen) for i, e in enumerate(data.get("extrinsics", []), start=1))
    clock = data.get("clock_facts", {})
    if not isinstance(clock, dict):
        raise RigError(f"{where}: clock_facts must be a table")
    _no_unknown(clock, _CLOCK_KEYS, f"{where}: clock_facts")
    return Rig(name=name, sensors=sensors, time_base=time_base, extrinsics=extrinsics, clock_facts=dict(clock),
               description=str(data.get("description", "")), path=Path(where) if base_dir is not None else None)


def _no_unknown(d: dict, allowed: set[str], where: str) -> None:
    unknown = sorted(set(d) - allowed)
    if unknown:
        raise RigError(f"{where}: unknown key {unknown[0]!r} (allowed: {', '.join(sorted(allowed))})")


def _sensor(s: Any, index: int, where, base_dir) -> SensorConfig:
    if not isinstance(s, dict):
        raise RigError(f"{where}: sensor #{index} must be a table")
    sid = s.get("id")
    at = f"{where}: sensor #{index}" + (f" ({sid!r})" if isinstance(sid, str) else "")
    _no_unknown(s, _SENSOR_KEYS, at)
    if not isinstance(sid, str) or not ID_PATTERN.match(sid):
        raise RigError(f"{at}: id must match [a-z0-9_]{{1,32}}, got {sid!r}")
    role = s.get("role")
    if role not in ROLES:
        raise RigError(f"{at}: role must be one of {', '.join(ROLES)}, got {role!r}")
    driver = s.get("driver")
    if not isinstance(driver, str) or not driver:
        raise RigError(f"{at}: missing driver (one of {', '.join(known_drivers())})")
    if driver not in known_drivers():
        raise RigError(f"{at}: unknown sensor driver {driver!r} (known: {', '.join(known_drivers())})")
    serial = s.get("serial")
    if isinstance(serial, int) and not isinstance(serial, bool):
        serial = str(serial)
    if not isinstance(serial, str) or not serial.strip():
        raise RigError(f"{at}: missing serial (every sensor names its device; see data_manifests/rig.md)")
    model = s.get("model")
    if model is not None and not isinstance(model, str):
        raise RigError(f"{at}: model must be a string")
    streams_raw = s.get("streams", {})
    if not isinstance(streams_raw, dict):
        raise RigError(f"{at}: streams must be a table of stream tables")
    streams = {n: _stream(n, v, at) for n, v in streams_raw.items()}
    for key in ("sync", "options"):
        if not isinstance(s.get(key, {}), dict):
            raise RigError(f"{at}: {key} must be a table")
    options = dict(s.get("options", {}))
    for key in PATH_OPTIONS:
        if key in options:
            if not isinstance(options[key], str):
                raise RigError(f"{at}: options.{key} must be a path string")
            if base_dir is not None:
                options[key] = str((Path(base_dir) / options[key]).resolve())
    return SensorConfig(id=sid, role=role, driver=driver, serial=serial.strip(), streams=streams,
                        sync=dict(s.get("sync", {})), options=options, model=model)


def _stream(name: str, v: Any, at: str) -> StreamSettings:
    where = f"{at}: streams.{name}"
    if not ID_PATTERN.match(name):
        raise RigError(f"{where}: stream name must match [a-z0-9_]{{1,32}}")
    if not isinstance(v, dict):
        raise RigError(f"{where}: must be a table")
    _no_unknown(v, _STREAM_KEYS, where)
    stype = v.get("type", name if name in STREAM_TYPES else None)
    if stype not in STREAM_TYPES:
        raise RigError(f"{where}: type must be one of {', '.join(STREAM_TYPES)} (give 'type' for a stream named {name!r})")
    for key in ("width", "height"):
        if key in v and not (isinstance(v[key], int) and not isinstance(v[key], bool) and v[key] > 0):
            raise RigError(f"{where}: {key} must be a positive integer, got {v[key]!r}")
    fps = v.get("fps")
    if fps is not None and not (isinstance(fps, (int, float)) and not isinstance(fps, bool) and fps > 0):
        raise RigError(f"{where}: fps must be a positive number, got {fps!r}")
    enc = v.get("encoding")
    if enc is not None:
        if enc not in ENCODINGS:
            raise RigError(f"{where}: encoding must be one of {', '.join(ENCODINGS)}, got {enc!r}")
        if (stype == "color") == (enc == "png16"):
            raise RigError(f"{where}: encoding {enc!r} does not fit a {stype} stream")
    return StreamSettings(name=name, type=stype, width=v.get("width"), height=v.get("height"),
                          fps=None if fps is None else float(fps), encoding=enc)


def _extrinsic(e: Any, index: int, where, sensor_ids: set[str]) -> dict:
    at = f"{where}: extrinsics #{index}"
    if not isinstance(e, dict):
        raise RigError(f"{at}: must be a table")
    _no_unknown(e, _EXTRINSIC_KEYS, at)
    for end in ("dst", "src"):
        if e.get(end) not in sensor_ids:
            raise RigError(f"{at}: {end} must name a sensor of the rig, got {e.get(end)!r}")
    try:
        T = Transform.from_list(e.get("T"))
    except (CalibrationError, ValueError, TypeError) as exc:
        raise RigError(f"{at}: T: {exc}") from None
    return {"dst": e["dst"], "src": e["src"], "T": T.to_list(), "source": str(e.get("source", "declared"))}
