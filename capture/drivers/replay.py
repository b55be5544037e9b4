"""The replay driver: plays one sensor of a recorded session back in real time.

It lets the recorder be tested and benchmarked without hardware: frames come out at the
times they were recorded (sleeping until each is due), with the source's frame numbers and
device timestamps, stamped with the host clock when delivered, exactly like a live device.

Rig file::

    [[sensor]]
    id = "lq"
    role = "lq"
    driver = "replay"
    serial = "lq"                 # the source sensor: its id or its serial in the source session
    [sensor.options]
    session = "../sim/lq-hq"      # source session folder (relative to the rig file)
    loop = true                   # start again after the last frame (numbers and times continue)
    speed = 1.0                   # 2.0 = twice real time
    preload = true                # decode every frame at open (playback then costs ~nothing)
    drop_frames = [5, 6, 40]      # source frame numbers never delivered (injected drops)
    duplicate_frames = [10]       # source frame numbers delivered twice (injected duplicates)
    drop_rate = 0.0               # or random drops / duplicates, reproducible with seed
    duplicate_rate = 0.0
    seed = 0

Streams: the rig's ``[sensor.streams.NAME]`` pick which source streams play (all when none
are given); a requested size or frame rate the source does not have is a DeviceError, as a
real device refuses a mode it cannot do. Replays of one source session opened together share
one start instant, so the relative timing of their sensors (e.g. a simulated LQ/HQ time
shift) is kept.

Host timestamps are the real arrival times on this machine (CLOCK_MONOTONIC), so they carry the
machine's scheduling jitter like a live recording; frame numbers and device timestamps are the
source's (shifted by whole loops when looping).

What was injected is in :attr:`ReplayDriver.injected` (per stream: ``dropped``, ``duplicated``,
and the frame numbers), for tests to compare with what the recorder reports.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from capture.drivers.base import (DeviceInfo, Driver, Frame, SensorConfig, SensorDescription, StreamDescription,
                                  host_clock_us, register)
from capture.errors import DeviceError, RigError, SessionFormatError
from capture.session import Session, open_session

_OPTIONS = {"session", "loop", "speed", "preload", "drop_frames", "duplicate_frames", "drop_rate", "duplicate_rate",
            "seed", "start_delay_s"}
#: Lead time between the first read of a group of replays and their first frame (µs).
_START_LEAD_US = 50_000


@dataclass(frozen=True)
class _Event:
    t_us: int            # source time (on the source's time base) of the frame
    stream: str
    frame_number: int
    device_timestamp_us: int


class _Group:
    """Replays of one source session opened together share one start instant."""

    def __init__(self, t_min_us: int) -> None:
        self.t_min_us = t_min_us
        self.epoch_us: int | None = None


class _Epochs:
    """The current group per source; a group whose playback has started takes no new members
    (a replay opened later starts a new group: a new recording)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._current: dict[str, _Group] = {}

    def join(self, key: str, t_min_us: int) -> _Group:
        with self._lock:
            g = self._current.get(key)
            if g is None or g.epoch_us is not None:
                g = self._current[key] = _Group(t_min_us)
            g.t_min_us = min(g.t_min_us, t_min_us)
            return g

    def epoch(self, g: _Group, lead_us: int) -> tuple[int, int]:
        """(host µs at which source time ``t_min`` plays, ``t_min``); fixed by the group's first read."""
        with self._lock:
            if g.epoch_us is None:
                g.epoch_us = host_clock_us() + lead_us
            return g.epoch_us, g.t_min_us


_EPOCHS = _Epochs()
_CACHE_LOCK = threading.Lock()
_IMAGE_CACHE: dict[tuple, np.ndarray] = {}


def _cached_image(session: Session, sensor: str, stream: str, frame_number: int) -> np.ndarray:
    """Decoded source image, shared (read-only) by every replay of the same source in this process."""
    key = (str(session.root.resolve()), sensor, stream, frame_number)
    img = _IMAGE_CACHE.get(key)
    if img is None:
        img = session.read_image(sensor, stream, frame_number, verify=False)
        img.setflags(write=False)
        with _CACHE_LOCK:
            _IMAGE_CACHE[key] = img
    return img


def clear_cache() -> None:
    """Forget decoded source images (tests, long-running processes)."""
    with _CACHE_LOCK:
        _IMAGE_CACHE.clear()


@register
class ReplayDriver(Driver):
    """Plays one sensor of an existing session at its recorded frame rate (see module docstring)."""

    name = "replay"
    description = "plays a recorded or simulated session back in real time (no hardware)"

    def __init__(self, config: SensorConfig) -> None:
        super().__init__(config)
        self.check_config(config)
        o = config.options
        self.source_path = Path(o["session"])
        self.loop = bool(o.get("loop", False))
        self.speed = float(o.get("speed", 1.0))
        self.preload = bool(o.get("preload", True))
        self.start_delay_us = int(float(o.get("start_delay_s", 0.0)) * 1e6)
        self._closed = threading.Event()
        self._session: Session | None = None
        self._sensor = ""
        self._events: list[_Event] = []
        self._next = 0
        self._loop_index = 0
        self._frame_span = 0
        self._time_span_us = 0
        self._group: _Group | None = None
        self.injected: dict[str, dict] = {}

    @classmethod
    def check_config(cls, config: SensorConfig) -> None:
        o = config.options
        at = f"sensor {config.id!r} (replay)"
        unknown = sorted(set(o) - _OPTIONS)
        if unknown:
            raise RigError(f"{at}: unknown option {unknown[0]!r} (replay options: {', '.join(sorted(_OPTIONS))})")
        if "session" not in o:
            raise RigError(f"{at}: options.session (the session folder to play) is missing")
        for key in ("drop_frames", "duplicate_frames"):
            v = o.get(key, [])
            if not (isinstance(v, list) and all(isinstance(x, int) and not isinstance(x, bool) for x in v)):
                raise RigError(f"{at}: options.{key} must be a list of frame numbers")
        for key in ("drop_rate", "duplicate_rate"):
            v = o.get(key, 0.0)
            if not (isinstance(v, (int, float)) and 0.0 <= v < 1.0):
                raise RigError(f"{at}: options.{key} must be in [0, 1), got {v!r}")
        speed = o.get("speed", 1.0)
        if not (isinstance(speed, (int, float)) and not isinstance(speed, bool) and speed > 0):
            raise RigError(f"{at}: options.speed must be a positive number, got {speed!r}")

    # ------------------------------------------------------------------ open
    def open(self) -> SensorDescription:
        label = self.config.label
        try:
            s = open_session(self.source_path)
        except SessionFormatError as exc:
            raise DeviceError(f"{label}: cannot replay: {exc}") from None
        matches = [sid for sid, info in s.sensors.items() if self.config.serial in (sid, info.serial)]
        if not matches:
            raise DeviceError(f"{label}: source session {self.source_path} has no sensor with id or serial "
                              f"{self.config.serial!r} (it has {', '.join(s.sensors)})")
        self._session, self._sensor = s, matches[0]
        src = s.sensors[self._sensor]
        wanted = self.config.streams or {n: None for n in src.streams}
        streams = {}
        for name, req in wanted.items():
            if name not in src.streams:
                raise DeviceError(f"{label}: source sensor {self._sensor!r} has no stream {name!r} "
                                  f"(it has {', '.join(src.streams)})")
            info = src.streams[name]
            if req is not None:
                if (req.width or info.width, req.height or info.height) != (info.width, info.height):
                    raise DeviceError(f"{label}: stream {name} is {info.width}x{info.height} in the source, "
                                      f"cannot deliver {req.width}x{req.height}")
                if req.fps is not None and abs(req.fps - info.fps) > 1e-6:
                    raise DeviceError(f"{label}: stream {name} runs at {info.fps:g} fps in the source, cannot deliver {req.fps:g}")
            encoding = (req.encoding if req is not None and req.encoding else info.encoding)
            streams[name] = StreamDescription(name=name, type=info.type, width=info.width, height=info.height,
                                              fps=info.fps, encoding=encoding, intrinsics=info.intrinsics,
                                              depth_unit_m=info.depth_unit_m)
        self._build_schedule(s, streams)
        if self.preload:
            for e in self._events:
                _cached_image(s, self._sensor, e.stream, e.frame_number)
        manifest = s.manifest["sensors"][self._sensor]
        clock = dict(manifest.get("clock", {}))
        clock.update({"replayed_from": str(self.source_path), "source_sensor": self._sensor})
        self._group = _EPOCHS.join(str(self.source_path.resolve()), self._events[0].t_us if self._events else 0)
        return SensorDescription(model=src.model, serial=src.serial, streams=streams,
                                 firmware=manifest.get("firmware"), technology=manifest.get("technology", "unknown"),
                                 T_depth_color=src.T_depth_color, clock=clock)

    def _build_schedule(self, s: Session, streams: dict[str, StreamDescription]) -> None:
        o = self.config.options
        rng = np.random.default_rng(int(o.get("seed", 0)))
        drop, dup = set(o.get("drop_frames", [])), set(o.get("duplicate_frames", []))
        drop_rate, dup_rate = float(o.get("drop_rate", 0.0)), float(o.get("duplicate_rate", 0.0))
        events = []
        for name in streams:
            df = s.frames(self._sensor, name)
            t = df[f"{s.time_base}_timestamp_us"].to_numpy(np.int64)
            inj = self.injected.setdefault(name, {"dropped": 0, "duplicated": 0, "dropped_frames": [],
                                                  "duplicated_frames": []})
            for ti, fn, dev in zip(t, df["frame_number"].to_numpy(np.int64), df["device_timestamp_us"].to_numpy(np.int64)):
                fn = int(fn)
                e = _Event(int(ti), name, fn, int(dev))
                if fn in drop or (drop_rate and rng.random() < drop_rate):
                    inj["dropped"] += 1
                    inj["dropped_frames"].append(fn)
                    continue
                events.append(e)
                if fn in dup or (dup_rate and rng.random() < dup_rate):
                    inj["duplicated"] += 1
                    inj["duplicated_frames"].append(fn)
                    events.append(e)
        events.sort(key=lambda e: e.t_us)  # stable: a duplicate stays right after its original
        self._events = events
        if events:
            first = {n: s.frames(self._sensor, n) for n in streams}
            self._frame_span = max(int(df["frame_number"].max() - df["frame_number"].min()) + 1
                                   for df in first.values() if len(df))
            period = min(1e6 / st.fps for st in streams.values())
            self._time_span_us = int(events[-1].t_us - events[0].t_us + round(period))

    # ------------------------------------------------------------------ read / close
    def read(self, *, timeout_s: float) -> list[Frame] | None:
        if self._closed.is_set():
            return None
        if self._session is None:
            raise DeviceError(f"{self.config.label}: read() before open()")
        if self._next >= len(self._events):
            if not self.loop or not self._events:
                return None
            self._next, self._loop_index = 0, self._loop_index + 1
        epoch, t_min = _EPOCHS.epoch(self._group, _START_LEAD_US + self.start_delay_us)
        due = self._due_us(self._events[self._next], epoch, t_min)
        wait_us = due - host_clock_us()
        if wait_us > 0:
            if self._closed.wait(min(wait_us * 1e-6, timeout_s)):
                return None
            if host_clock_us() < due:
                return []
        out = []
        now = host_clock_us()
        while self._next < len(self._events) and self._due_us(self._events[self._next], epoch, t_min) <= now:
            out.append(self._frame(self._events[self._next]))
            self._next += 1
        return out

    def _due_us(self, e: _Event, epoch: int, t_min: int) -> int:
        t = e.t_us - t_min + self._loop_index * self._time_span_us
        return epoch + int(t / self.speed)

    def _frame(self, e: _Event) -> Frame:
        img = _cached_image(self._session, self._sensor, e.stream, e.frame_number)
        k = self._loop_index
        return Frame(stream=e.stream, frame_number=e.frame_number + k * self._frame_span,
                     device_timestamp_us=e.device_timestamp_us + k * self._time_span_us,
                     clock_domain="replay", host_timestamp_us=host_clock_us(), image=img)

    def close(self) -> None:
        self._closed.set()

    @classmethod
    def enumerate(cls) -> list[DeviceInfo]:
        return []  # nothing to connect: a replay names its source session in the rig file
