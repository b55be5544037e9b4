"""Luxonis OAK-D cameras (``depthai`` v3): stereo depth aligned to the colour camera, plus colour.

Pipeline (:func:`build_pipeline`): colour camera ``CAM_A`` -> colour output (RGB888i) at the
requested size; mono cameras ``CAM_B``/``CAM_C`` -> ``StereoDepth`` (left-right check, subpixel)
with the depth **aligned to CAM_A** and scaled to the colour size. Both streams therefore share
the colour camera's model, and ``T_depth_color`` is the identity.

Calibration comes from the device's EEPROM (``Device.readCalibration()``):
:func:`intrinsics_from_calibration` asks ``CalibrationHandler.getCameraIntrinsics(socket, w, h)``
(the SDK scales and centre-crops the factory intrinsics to the output size, as the camera's ISP
does) and ``getDistortionCoefficients`` (OpenCV order ``k1, k2, p1, p2, k3, k4, k5, k6, s1..s4,
tx, ty``; the thin-prism/tilt terms must be zero, else the model is refused);
:func:`transform_from_calibration` reads extrinsics in **metres** (the SDK's default unit is cm).

Per frame: the sequence number is the frame number; ``getTimestampDevice()`` (the device's
monotonic clock) is the device timestamp, domain ``"device"``; ``getTimestamp()`` (the device
time mapped to the host's steady clock by depthai's time sync) goes to the frame metadata as
``host_synced_timestamp_us``; the host timestamp is :func:`~capture.drivers.base.host_clock_us` at
arrival. Depth is ``uint16`` millimetres (``depth_unit_m = 0.001``), 0 = no measurement.

``depthai`` is imported lazily (it prints a USB warning on import), with its telemetry, crash
dump upload and start-up notifications off unless the environment says otherwise.

Rig file::

    [[sensor]]
    id = "lq"
    role = "lq"
    driver = "oakd"
    serial = "14442C10D13EABCE00"     # the device id (MX id) that `depthbench capture devices` lists
    [sensor.streams.depth]
    type = "depth"
    width = 640
    height = 400
    fps = 30
    [sensor.streams.color]
    type = "color"
    [sensor.options]
    preset = "DEFAULT"                # StereoDepth preset: DEFAULT, FAST_ACCURACY, FAST_DENSITY, ROBOTICS, ...
    [sensor.sync]
    role = "master"                   # external frame sync: "master" or "slave" (OAK with FSYNC)
"""
from __future__ import annotations

import datetime
import os
import threading
import time
from typing import Any, Mapping

import cv2
import numpy as np

from capture.camera import Intrinsics, Transform
from capture.drivers.base import (DeviceInfo, Driver, Frame, SensorConfig, SensorDescription, StreamDescription,
                                  host_clock_us, register)
from capture.errors import CalibrationError, DeviceError, RigError

DEPTH_UNIT_M = 0.001
DEFAULT_SIZE = (640, 400)
DEFAULT_FPS = 30.0
_ENV_DEFAULTS = {"DEPTHAI_TELEMETRY": "0", "DEPTHAI_DISABLE_FEEDBACK": "1",
                 "DEPTHAI_DISABLE_STARTUP_NOTIFICATIONS": "1", "DEPTHAI_DISABLE_CRASHDUMP_COLLECTION": "1"}
_OPTIONS = {"preset", "subpixel", "left_right_check", "extended_disparity"}


def dai():
    """The ``depthai`` module, imported on first use (telemetry and uploads off by default)."""
    for key, value in _ENV_DEFAULTS.items():
        os.environ.setdefault(key, value)
    try:
        import depthai
    except ImportError as exc:  # pragma: no cover - depthai is a dependency
        raise DeviceError(f"OAK-D support needs the depthai package ({exc})") from None
    return depthai


# ============================================================================ pure conversions
def timedelta_us(td: datetime.timedelta) -> int:
    """A ``datetime.timedelta`` (depthai timestamps) as exact int µs."""
    return (td.days * 86_400 + td.seconds) * 1_000_000 + td.microseconds


def _f32(value: float) -> float:
    return float(str(np.float32(value)))


def intrinsics_from_calibration(calib, socket, width: int, height: int) -> Intrinsics:
    """Intrinsics of camera ``socket`` at output size ``width x height`` from a ``dai.CalibrationHandler``."""
    d = dai()
    try:
        K = np.asarray(calib.getCameraIntrinsics(socket, int(width), int(height)), dtype=np.float64)
        coeffs = [float(c) for c in calib.getDistortionCoefficients(socket)]
        model = calib.getDistortionModel(socket)
    except RuntimeError as exc:
        raise CalibrationError(f"camera {socket}: no usable calibration ({' '.join(str(exc).split())})") from None
    if model != d.CameraModel.Perspective:
        raise CalibrationError(f"camera {socket}: lens model {model} is not supported (only Perspective)")
    extra = coeffs[8:]
    if any(abs(c) > 0 for c in extra):
        raise CalibrationError(f"camera {socket}: thin-prism/tilt distortion terms {extra} are not supported")
    first8 = tuple(_f32(c) for c in (coeffs + [0.0] * 8)[:8])
    fx, fy, cx, cy = (_f32(v) for v in (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))
    if not any(first8):
        return Intrinsics(int(width), int(height), fx, fy, cx, cy)
    return Intrinsics(int(width), int(height), fx, fy, cx, cy, "opencv", first8)


def transform_from_calibration(calib, src, dst) -> Transform:
    """``T_dst_src`` in metres from a ``dai.CalibrationHandler`` (maps points of ``src`` into ``dst``)."""
    d = dai()
    try:
        M = np.asarray(calib.getCameraExtrinsics(src, dst, unit=d.LengthUnit.METER), dtype=np.float64)
    except RuntimeError as exc:
        raise CalibrationError(f"no extrinsics from {src} to {dst} ({' '.join(str(exc).split())})") from None
    M[:3, :] = np.vectorize(_f32)(M[:3, :])
    return Transform(M)


def imgframe_to_frame(msg, stream: str, *, host_timestamp_us: int | None = None) -> Frame:
    """A ``dai.ImgFrame`` as a :class:`Frame`: depth RAW16 -> uint16 mm, colour -> RGB uint8."""
    d = dai()
    t = msg.getType()
    if stream == "depth":
        if t != d.ImgFrame.Type.RAW16:
            raise DeviceError(f"oakd {stream}: expected RAW16 depth frames, got {t}")
        image = np.array(msg.getFrame(), dtype=np.uint16, copy=True).reshape(msg.getHeight(), msg.getWidth())
    elif t == d.ImgFrame.Type.RGB888i:
        image = np.array(msg.getFrame(), dtype=np.uint8, copy=True).reshape(msg.getHeight(), msg.getWidth(), 3)
    else:
        bgr = msg.getCvFrame()
        image = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB) if bgr.ndim == 3 else cv2.cvtColor(bgr, cv2.COLOR_GRAY2RGB)
    metadata = {"host_synced_timestamp_us": timedelta_us(msg.getTimestamp())}
    host = host_clock_us() if host_timestamp_us is None else int(host_timestamp_us)
    return Frame(stream=stream, frame_number=int(msg.getSequenceNum()),
                 device_timestamp_us=timedelta_us(msg.getTimestampDevice()), clock_domain="device",
                 host_timestamp_us=host, image=image, metadata=metadata)


# ============================================================================ the pipeline
def build_pipeline(pipeline, *, size: tuple[int, int] = DEFAULT_SIZE, fps: float = DEFAULT_FPS,
                   streams: tuple[str, ...] = ("depth", "color"), options: Mapping[str, Any] | None = None) -> dict:
    """Add the camera, stereo and alignment nodes to ``pipeline``; returns ``{stream: node output}``.

    Needs a pipeline bound to a device (``dai.Pipeline(device)``): on a host-only pipeline
    (``dai.Pipeline(False)``) it raises :class:`DeviceError`."""
    d = dai()
    options = dict(options or {})
    w, h = int(size[0]), int(size[1])
    try:
        outputs = {}
        color = pipeline.create(d.node.Camera).build(d.CameraBoardSocket.CAM_A)
        if "color" in streams:
            outputs["color"] = color.requestOutput((w, h), type=d.ImgFrame.Type.RGB888i, fps=fps)
        if "depth" in streams:
            left = pipeline.create(d.node.Camera).build(d.CameraBoardSocket.CAM_B)
            right = pipeline.create(d.node.Camera).build(d.CameraBoardSocket.CAM_C)
            stereo = pipeline.create(d.node.StereoDepth)
            preset = str(options.get("preset", "DEFAULT")).upper()
            stereo.setDefaultProfilePreset(getattr(d.node.StereoDepth.PresetMode, preset))
            left.requestFullResolutionOutput(fps=fps).link(stereo.left)
            right.requestFullResolutionOutput(fps=fps).link(stereo.right)
            stereo.setLeftRightCheck(bool(options.get("left_right_check", True)))
            stereo.setSubpixel(bool(options.get("subpixel", True)))
            stereo.setExtendedDisparity(bool(options.get("extended_disparity", False)))
            stereo.setDepthAlign(d.CameraBoardSocket.CAM_A)
            stereo.setOutputSize(w, h)
            outputs["depth"] = stereo.depth
        return outputs
    except RuntimeError as exc:
        text = " ".join(str(exc).split())
        if "host only" in text.lower():
            raise DeviceError(f"oakd: the stereo/camera pipeline needs a device (host-only pipeline: {text})") from None
        raise DeviceError(f"oakd: cannot build the pipeline: {text}") from None


# ============================================================================ the driver
@register
class OakDDriver(Driver):
    """A live Luxonis OAK-D (any OAK with a colour camera and a stereo pair)."""

    name = "oakd"
    description = "Luxonis OAK-D (depthai v3): stereo depth aligned to colour, device calibration"

    def __init__(self, config: SensorConfig) -> None:
        super().__init__(config)
        self._device = self._pipeline = None
        self._queues: dict[str, Any] = {}
        self._closed = threading.Event()

    @classmethod
    def enumerate(cls) -> list[DeviceInfo]:
        d = dai()
        out = []
        for info in d.Device.getAllAvailableDevices():
            out.append(DeviceInfo(driver="oakd", serial=info.getDeviceId(), model=f"OAK ({info.platform.name})",
                                  details={"name": info.name, "state": info.state.name,
                                           "protocol": info.protocol.name}))
        return out

    @classmethod
    def check_config(cls, config: SensorConfig) -> None:
        for name, st in config.streams.items():
            if name not in ("depth", "color") or st.type != name:
                raise RigError(f"sensor {config.label}: OAK-D streams are 'depth' and 'color', not {name!r} ({st.type})")
        sizes = {(st.width, st.height) for st in config.streams.values() if st.width or st.height}
        rates = {st.fps for st in config.streams.values() if st.fps}
        if len(sizes) > 1 or len(rates) > 1:
            raise RigError(f"sensor {config.label}: OAK-D depth is aligned to colour, so both streams need the same "
                           "size and frame rate")
        unknown = set(config.options) - _OPTIONS
        if unknown:
            raise RigError(f"sensor {config.label}: unknown OAK-D option {sorted(unknown)[0]!r} (known: {', '.join(sorted(_OPTIONS))})")
        if set(config.sync) - {"role"} or config.sync.get("role", "master") not in ("master", "slave"):
            raise RigError(f"sensor {config.label}: OAK-D sync takes role = \"master\" or \"slave\"")

    def _settings(self) -> tuple[tuple[int, int], float, tuple[str, ...]]:
        streams = tuple(self.config.streams) or ("depth", "color")
        w = next((st.width for st in self.config.streams.values() if st.width), None) or DEFAULT_SIZE[0]
        h = next((st.height for st in self.config.streams.values() if st.height), None) or DEFAULT_SIZE[1]
        fps = next((st.fps for st in self.config.streams.values() if st.fps), None) or DEFAULT_FPS
        return (int(w), int(h)), float(fps), streams

    def open(self) -> SensorDescription:
        self.check_config(self.config)
        d = dai()
        infos = d.Device.getAllAvailableDevices()
        ids = [i.getDeviceId() for i in infos]
        match = [i for i in infos if self.config.serial in (i.getDeviceId(), i.name)]
        if not match:
            raise DeviceError(f"{self.config.label}: no OAK device with id {self.config.serial} found "
                              f"(connected: {', '.join(ids) if ids else 'none'})")
        size, fps, streams = self._settings()
        try:
            self._device = d.Device(match[0])
            if "role" in self.config.sync:
                role = d.ExternalFrameSyncRole.MASTER if self.config.sync["role"] == "master" else d.ExternalFrameSyncRole.SLAVE
                self._device.setExternalFrameSyncRole(role)
            calib = self._device.readCalibration()
            self._pipeline = d.Pipeline(self._device)
            outputs = build_pipeline(self._pipeline, size=size, fps=fps, streams=streams, options=self.config.options)
            self._queues = {n: o.createOutputQueue(maxSize=64, blocking=False) for n, o in outputs.items()}
            K = intrinsics_from_calibration(calib, d.CameraBoardSocket.CAM_A, *size)
            self._pipeline.start()
        except (RuntimeError, CalibrationError) as exc:
            self.close()
            raise DeviceError(f"{self.config.label}: cannot start the OAK pipeline: {' '.join(str(exc).split())}") from None
        descs = {}
        for n in streams:
            asked = self.config.streams.get(n)
            encoding = (asked.encoding if asked is not None and asked.encoding else None) or (
                "png16" if n == "depth" else "png")
            descs[n] = StreamDescription(name=n, type=n, width=size[0], height=size[1], fps=fps, encoding=encoding,
                                         intrinsics=K, depth_unit_m=DEPTH_UNIT_M if n == "depth" else None)
        model = self._device.getProductName() or "Luxonis OAK-D"
        clock = {"domain": "device", "host_synced_timestamps": "frame metadata host_synced_timestamp_us",
                 "depth_aligned_to": "CAM_A"}
        if "role" in self.config.sync:
            clock["external_sync_role"] = self.config.sync["role"]
        return SensorDescription(model=model if "oak" in model.lower() else f"Luxonis {model}",
                                 serial=self._device.getDeviceId(), streams=descs, firmware=None,
                                 technology="stereo", T_depth_color=Transform.identity(), clock=clock)

    def read(self, *, timeout_s: float) -> list[Frame] | None:
        if self._closed.is_set() or self._pipeline is None:
            return None
        deadline = time.monotonic() + timeout_s
        out: list[Frame] = []
        while True:
            try:
                for name, q in self._queues.items():
                    while (msg := q.tryGet()) is not None:
                        out.append(imgframe_to_frame(msg, name))
            except RuntimeError as exc:
                if self._closed.is_set():
                    return None
                raise DeviceError(f"{self.config.label}: the device stopped delivering frames: "
                                  f"{' '.join(str(exc).split())}") from None
            if out or time.monotonic() >= deadline:
                return out
            if not self._pipeline.isRunning():
                raise DeviceError(f"{self.config.label}: the OAK pipeline stopped")
            time.sleep(0.002)

    def close(self) -> None:
        self._closed.set()
        for obj, method in ((self._pipeline, "stop"), (self._device, "close")):
            if obj is not None:
                try:
                    getattr(obj, method)()
                except Exception:  # closing must not raise
                    pass
        self._pipeline = self._device = None
