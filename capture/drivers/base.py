"""The sensor driver interface and the driver registry.

Every live source of RGB-D frames (a RealSense camera, an OAK-D, the replay of a recorded
session) is a :class:`Driver` subclass registered under a short name (``"realsense"``,
``"oakd"``, ``"replay"``...). A rig file (``data_manifests/rig.md``) names the driver of each
sensor; the recorder (``capture/recorder.py``) opens every sensor of the rig, reads frames from
each in its own thread and writes them into a session folder.

Life cycle of a driver (one physical sensor)::

    drv = driver_class("realsense")(config)     # config: SensorConfig from the rig file; no I/O yet
    desc = drv.open()                           # start streaming; -> SensorDescription
    while True:
        frames = drv.read(timeout_s=0.5)        # -> list[Frame]; [] = nothing yet; None = source ended
        if frames is None:
            break
        ...
    drv.close()                                 # idempotent; safe after a failed open()

``read`` is called from one reader thread per driver; ``close`` may be called from another
thread to end a blocked ``read`` (it then returns ``None`` or ``[]``). Drivers raise
:class:`capture.errors.DeviceError` with a one-line message naming the sensor (driver and
serial) and the problem: no device with that serial, a stream mode the device cannot do, the
SDK missing, the device disappearing.

Units and clocks (the suite's conventions, ``../shared/DESIGN.md``):

* ``Frame.image``: depth ``(H, W) uint16`` counts in the stream's ``depth_unit_m`` with 0 = no
  measurement (what the device delivers; the recorder writes it unchanged), or ``(H, W) float32``
  metres with NaN = no measurement; colour ``(H, W, 3) uint8`` **RGB**; IR ``(H, W) uint16``.
* ``Frame.device_timestamp_us``: int64 µs on the device's clock, whose domain is named by
  ``Frame.clock_domain`` (e.g. RealSense ``"hardware_clock"``, ``"global_time"``,
  ``"system_time"``; ``"device"`` when the SDK does not say).
* ``Frame.host_timestamp_us``: int64 µs when the frame reached the host, always read with
  :func:`host_clock_us` = ``time.monotonic_ns() // 1000`` (CLOCK_MONOTONIC: one clock for every
  sensor of a process, never stepped by NTP). The recorder writes the UTC time of the
  monotonic zero into ``session.json`` (``source.host_clock``) so wall time can be recovered.
  Drivers must stamp frames as early as possible (right after the SDK hands them over), not
  when they are written.
* ``Frame.frame_number``: the device's frame counter (strictly increasing per stream when
  nothing is lost; gaps are drops, repeats are duplicates; the recorder counts both).

Registry: :func:`register` (a class decorator) adds a driver under ``cls.name``. Drivers that
need an SDK live in their own module and are imported lazily through :data:`DRIVER_MODULES`,
so listing or recording with one driver never imports another driver's SDK.
``Driver.enumerate()`` lists connected devices (``depthbench capture devices``);
:func:`enumerate_devices` asks every known driver and reports per driver what went wrong
instead of failing.
"""
from __future__ import annotations

import importlib
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar, Iterator, Mapping

import numpy as np

from capture.camera import Intrinsics, Transform
from capture.errors import DeviceError, RigError
from capture.session import StreamInfo

#: Driver name -> module that defines (and registers) it. A module is imported the first time
#: its driver is asked for. Add a line here when a new driver module lands.
DRIVER_MODULES: dict[str, str] = {
    "realsense": "capture.drivers.realsense",
    "oakd": "capture.drivers.oakd",
    "azure_kinect": "capture.drivers.azure_kinect",
    "replay": "capture.drivers.replay",
}

STREAM_TYPES = ("depth", "color", "ir")
ENCODINGS = ("png16", "png", "jpeg")


def host_clock_us() -> int:
    """The host clock of every ``Frame.host_timestamp_us``: ``time.monotonic_ns() // 1000`` (int µs)."""
    return time.monotonic_ns() // 1000


def host_clock_utc_offset_us() -> int:
    """UTC time (µs since the Unix epoch) of host-clock zero: ``utc_us = host_us + offset``."""
    return time.time_ns() // 1000 - host_clock_us()


# ----------------------------------------------------------------------------- rig-side settings
@dataclass(frozen=True)
class StreamSettings:
    """What the rig file asks of one stream. ``None`` = the driver's default.

    ``encoding`` is the on-disk encoding the recorder uses (``png16`` for depth/IR, ``png`` or
    ``jpeg`` for colour)."""

    name: str
    type: str
    width: int | None = None
    height: int | None = None
    fps: float | None = None
    encoding: str | None = None


@dataclass(frozen=True)
class SensorConfig:
    """One ``[[sensor]]`` table of a rig file (see ``data_manifests/rig.md``).

    Attributes:
        id: sensor id in the session (``^[a-z0-9_]{1,32}$``), e.g. ``"lq"``, ``"hq"``, ``"view0"``.
        role: ``"lq"``, ``"hq"`` or ``"view"``.
        driver: registry name, e.g. ``"realsense"``.
        serial: which device (for ``replay``: the source sensor's id or serial).
        streams: requested streams by name (``"depth"``, ``"color"``, ``"ir"``).
        sync: hardware-sync settings, e.g. ``{"inter_cam_sync_mode": 1}`` (RealSense: 0 default,
            1 master, 2 slave, 3 full slave), ``{"role": "master"}``. Driver-specific keys.
        options: any other driver-specific settings (``session`` for replay, ``visual_preset``,
            ``emitter_enabled``...).
        model: optional expected model name (a driver may check it).
    """

    id: str
    role: str
    driver: str
    serial: str
    streams: Mapping[str, StreamSettings]
    sync: Mapping[str, Any] = field(default_factory=dict)
    options: Mapping[str, Any] = field(default_factory=dict)
    model: str | None = None

    @property
    def label(self) -> str:
        """``"lq (realsense 123456)"``: how messages name this sensor."""
        return f"{self.id} ({self.driver} {self.serial})"


# ----------------------------------------------------------------------------- device-side facts
@dataclass(frozen=True)
class StreamDescription(StreamInfo):
    """One stream as the device actually delivers it (after ``open``): a session
    :class:`~capture.session.StreamInfo` whose fields a driver filled, checked on creation.

    Attributes:
        name: stream name in the session (``"depth"``, ``"color"``, ``"ir"``).
        type: ``"depth"``, ``"color"`` or ``"ir"``.
        width, height: pixels.
        fps: nominal frame rate, frames per second.
        encoding: on-disk encoding: ``"png16"`` (depth, IR), ``"png"`` or ``"jpeg"`` (colour).
        intrinsics: the stream's camera model (distortion in OpenCV order).
        depth_unit_m: metres per depth count (depth streams only), e.g. 0.001.
    """

    def __post_init__(self) -> None:
        if self.type not in STREAM_TYPES:
            raise DeviceError(f"stream {self.name}: unknown type {self.type!r} (expected one of {STREAM_TYPES})")
        if self.encoding not in ENCODINGS:
            raise DeviceError(f"stream {self.name}: unknown encoding {self.encoding!r} (expected one of {ENCODINGS})")
        if self.type == "depth" and not (self.depth_unit_m and self.depth_unit_m > 0):
            raise DeviceError(f"stream {self.name}: a depth stream needs a positive depth_unit_m")


@dataclass(frozen=True)
class SensorDescription:
    """What an opened device says about itself.

    Attributes:
        model: e.g. ``"Intel RealSense D415"``.
        serial: the device's serial number.
        streams: the delivered streams by name.
        firmware: firmware version, when known.
        technology: ``"stereo"``, ``"tof"``, ``"structured_light"``, ``"lidar"`` or ``"unknown"``.
        T_depth_color: factory transform mapping colour-camera points into the depth camera (metres).
        clock: facts about the device clock (domain, whether global time is on...), free-form JSON.
    """

    model: str
    serial: str
    streams: Mapping[str, StreamDescription]
    firmware: str | None = None
    technology: str = "unknown"
    T_depth_color: Transform | None = None
    clock: Mapping[str, Any] = field(default_factory=dict)

    def to_manifest(self, role: str) -> dict:
        """The sensor's entry of ``session.json`` (without ``frames``, which the writer adds)."""
        d: dict[str, Any] = {"role": role, "model": self.model, "serial": self.serial, "technology": self.technology,
                             "streams": {n: s.to_manifest() for n, s in self.streams.items()}}
        if self.firmware:
            d["firmware"] = self.firmware
        if self.T_depth_color is not None:
            d["T_depth_color"] = self.T_depth_color.to_list()
        if self.clock:
            d["clock"] = dict(self.clock)
        return d


@dataclass(frozen=True)
class Frame:
    """One image from one stream, with its counters and clocks (see the module docstring for units).

    Attributes:
        stream: stream name (a key of ``SensorDescription.streams``).
        frame_number: device frame counter.
        device_timestamp_us: int µs on the device clock named by ``clock_domain``.
        clock_domain: e.g. ``"hardware_clock"``, ``"global_time"``, ``"system_time"``, ``"device"``.
        host_timestamp_us: int µs from :func:`host_clock_us` when the frame reached the host.
        image: depth ``(H, W) uint16`` counts (or float32 metres, NaN = none); colour
            ``(H, W, 3) uint8`` RGB; IR ``(H, W) uint16``.
        metadata: anything else the SDK reports per frame (exposure, laser power...), optional.
    """

    stream: str
    frame_number: int
    device_timestamp_us: int
    clock_domain: str
    host_timestamp_us: int
    image: np.ndarray
    metadata: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class DeviceInfo:
    """A connected device as ``Driver.enumerate()`` reports it (``depthbench capture devices``)."""

    driver: str
    serial: str
    model: str
    firmware: str | None = None
    details: Mapping[str, Any] = field(default_factory=dict)


# ----------------------------------------------------------------------------- the interface
class Driver(ABC):
    """One sensor. Subclasses set :attr:`name` and implement ``open``, ``read``, ``close``, ``enumerate``.

    The constructor only stores the config (no I/O); :meth:`check_config` (a classmethod) may
    reject settings early so that a bad rig file fails before any device is opened.
    """

    #: Registry name used in rig files (``driver = "realsense"``).
    name: ClassVar[str] = ""
    #: One-line description for ``depthbench capture devices``.
    description: ClassVar[str] = ""

    def __init__(self, config: SensorConfig) -> None:
        self.config = config

    @classmethod
    def enumerate(cls) -> list[DeviceInfo]:
        """Devices of this kind connected now ([] when none). Raise DeviceError if the SDK is unusable."""
        return []

    @classmethod
    def check_config(cls, config: SensorConfig) -> None:
        """Raise :class:`RigError` (one line naming the sensor) for settings this driver cannot use."""

    @abstractmethod
    def open(self) -> SensorDescription:
        """Connect to the device, start its streams; return what it actually delivers."""

    @abstractmethod
    def read(self, *, timeout_s: float) -> list[Frame] | None:
        """Frames that arrived since the last call, waiting at most ``timeout_s`` for the first.

        Returns ``[]`` when nothing arrived in time and ``None`` when the source has ended
        (a recording played to its end, or :meth:`close` was called)."""

    @abstractmethod
    def close(self) -> None:
        """Stop streaming and release the device. Idempotent; callable from another thread."""

    def frames(self, *, timeout_s: float = 1.0) -> Iterator[Frame]:
        """Iterate over frames until the source ends (convenience over :meth:`read`)."""
        while True:
            batch = self.read(timeout_s=timeout_s)
            if batch is None:
                return
            yield from batch

    def __enter__(self) -> "Driver":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# ----------------------------------------------------------------------------- the registry
_REGISTRY: dict[str, type[Driver]] = {}


def register(cls: type[Driver]) -> type[Driver]:
    """Class decorator: make ``cls`` available under ``cls.name``."""
    if not cls.name:
        raise TypeError(f"{cls.__name__}: a driver needs a non-empty 'name'")
    _REGISTRY[cls.name] = cls
    return cls


def known_drivers() -> list[str]:
    """Every driver name a rig file may use (registered or importable on demand), sorted."""
    return sorted(set(DRIVER_MODULES) | set(_REGISTRY))


def driver_class(name: str) -> type[Driver]:
    """The driver registered as ``name``, importing its module if needed.

    Raises :class:`RigError` for an unknown name and :class:`DeviceError` when the driver's
    module cannot be imported (its SDK missing)."""
    if name in _REGISTRY:
        return _REGISTRY[name]
    module = DRIVER_MODULES.get(name)
    if module is None:
        raise RigError(f"unknown sensor driver {name!r} (known: {', '.join(known_drivers())})")
    try:
        importlib.import_module(module)
    except ImportError as exc:
        raise DeviceError(f"driver {name!r} is not available: {exc}") from None
    if name not in _REGISTRY:
        raise DeviceError(f"driver {name!r}: module {module} did not register it")
    return _REGISTRY[name]


@dataclass(frozen=True)
class DriverListing:
    """What one driver reported for :func:`enumerate_devices`: devices, or the problem."""

    driver: str
    devices: list[DeviceInfo]
    problem: str | None = None


def enumerate_devices(names: list[str] | None = None) -> list[DriverListing]:
    """Ask each driver (all known ones by default) for its connected devices; never raises for one driver."""
    out = []
    for name in names or known_drivers():
        try:
            out.append(DriverListing(name, list(driver_class(name).enumerate())))
        except Exception as exc:  # a broken SDK must not hide the other drivers' devices
            out.append(DriverListing(name, [], f"{type(exc).__name__}: {exc}".splitlines()[0]))
    return out
