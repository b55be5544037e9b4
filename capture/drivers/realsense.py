"""Intel RealSense cameras (``pyrealsense2``): live devices and ``.db3`` recordings.

One frame source, :class:`RealSenseSource`, serves both a live camera (:class:`RealSenseDriver`,
registered as ``"realsense"``) and the playback of a recording
(:func:`open_recording`, used by ``depthbench capture import realsense``), so the code that
turns SDK frames into :class:`~capture.drivers.base.Frame` objects is the code the recording
round trip tests.

What is read per device: model, serial, firmware, depth scale (metres per count), every stream's
factory intrinsics, the colour-to-depth extrinsics (``T_depth_color``), and per frame the frame
counter, the frame timestamp with its clock domain (``hardware_clock``, ``global_time`` when global
time is on, ``system_time``) and the per-frame metadata the SDK reports (sensor and frame
timestamps, time of arrival, exposure, laser power...).

SDK conventions converted here:

* timestamps are milliseconds as ``double`` -> ``int`` µs (``round(ms * 1000)``);
* intrinsics, depth units and extrinsics are ``float32`` -> the shortest decimal that is the same
  ``float32`` (``600.5``, not ``600.5000000001``; ``np.float32(value)`` gives the SDK's number back);
* ``rs.extrinsics.rotation`` is **column-major**;
* distortion ``brown_conrady`` is OpenCV's model with the same coefficient order
  (k1, k2, p1, p2, k3). ``inverse_brown_conrady`` (D400 colour cameras) and
  ``modified_brown_conrady`` are, in librealsense 2.5x, both the forward model with the tangential
  terms applied after the radial factor (``rs2_project_point_to_pixel``); that differs from OpenCV
  only in second-order tangential terms and is converted to the closest OpenCV model by a linear
  least-squares fit over the image (residual recorded in ``source.notes``; over
  :data:`MAX_FIT_ERROR_PX` it is an error). Fisheye models are refused.

Rig file (``data_manifests/rig.md``)::

    [[sensor]]
    id = "lq"
    role = "lq"
    driver = "realsense"
    serial = "123456789012"
    [sensor.streams.depth]
    type = "depth"
    width = 848
    height = 480
    fps = 30
    [sensor.streams.color]
    type = "color"
    width = 1280
    height = 720
    fps = 30
    [sensor.sync]
    inter_cam_sync_mode = 1      # 0 default, 1 master, 2 slave, 3 full slave (D400)
    [sensor.options]
    global_time = true           # rs.option.global_time_enabled (device timestamps on the host clock)
    emitter_enabled = 1          # any rs.option name with a number sets that option on the depth sensor
"""
from __future__ import annotations

import logging
import queue
import sqlite3
import threading
from collections import Counter
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping

import cv2
import numpy as np
import pyrealsense2 as rs

from capture.camera import Intrinsics, Transform
from capture.drivers.base import (DeviceInfo, Driver, Frame, SensorConfig, SensorDescription, StreamDescription,
                                  StreamSettings, host_clock_us, register)
from capture.errors import CalibrationError, DeviceError, RigError, SessionFormatError

log = logging.getLogger(__name__)

#: Largest residual (pixels, anywhere in the image) accepted when a non-OpenCV distortion model is
#: converted to OpenCV coefficients (a D455 colour camera's model fits to ~0.013 px in the far corners).
MAX_FIT_ERROR_PX = 0.05

#: Our stream name -> (SDK stream type, SDK stream index; None = any).
STREAM_KINDS: dict[str, tuple[Any, int | None]] = {
    "depth": (rs.stream.depth, None),
    "color": (rs.stream.color, None),
    "ir": (rs.stream.infrared, 1),
    "ir2": (rs.stream.infrared, 2),
}
_STREAM_TYPE_NAME = {"depth": "depth", "color": "color", "ir": "ir", "ir2": "ir"}
#: Pixel formats we read per stream type, best first.
_FORMATS = {
    "depth": (rs.format.z16,),
    "color": (rs.format.rgb8, rs.format.bgr8, rs.format.rgba8, rs.format.bgra8, rs.format.yuyv, rs.format.uyvy),
    "ir": (rs.format.y16, rs.format.y8),
}
#: Topic names of image data in librealsense ROS2 recordings: /device_0/sensor_1/Color_0/image/data...
_TOPIC_STREAM = {"Depth": rs.stream.depth, "Color": rs.stream.color, "Infrared": rs.stream.infrared}
#: Per-frame metadata recorded with each frame when the SDK supports it.
METADATA_FIELDS = ("frame_counter", "frame_timestamp", "sensor_timestamp", "time_of_arrival", "backend_timestamp",
                   "actual_exposure", "gain_level", "auto_exposure", "frame_laser_power", "frame_laser_power_mode",
                   "exposure_priority", "actual_fps", "frame_emitter_mode", "white_balance", "brightness", "contrast",
                   "raw_frame_size")
_METADATA = [(n, getattr(rs.frame_metadata_value, n)) for n in METADATA_FIELDS if hasattr(rs.frame_metadata_value, n)]
#: Sync keys a rig file may set (rs.option names); see :meth:`RealSenseDriver.check_config`.
SYNC_OPTIONS = ("inter_cam_sync_mode", "output_trigger_enabled")


# ============================================================================ pure conversions
def f32(value: float) -> float:
    """The shortest decimal that rounds to the same float32 as ``value`` (the SDK's float32 fields)."""
    return float(str(np.float32(value)))


def timestamp_ms_to_us(ms: float) -> int:
    """SDK timestamp (milliseconds, double) to int µs."""
    return int(round(float(ms) * 1000.0))


def transform_from_rs(extrinsics) -> Transform:
    """``rs.extrinsics`` (rotation column-major, translation metres) to a :class:`Transform`.

    ``a.get_extrinsics_to(b)`` maps points of stream ``a`` into stream ``b``: it is ``T_b_a``."""
    R = np.array([f32(v) for v in extrinsics.rotation], dtype=np.float64).reshape(3, 3).T
    t = np.array([f32(v) for v in extrinsics.translation], dtype=np.float64)
    # float32 rotations are orthonormal to ~1e-7, which Transform accepts: keep the SDK's numbers.
    try:
        return Transform.from_rt(R, t)
    except CalibrationError:
        u, _, vt = np.linalg.svd(R)
        if np.abs(u @ vt - R).max() > 1e-4:
            raise CalibrationError(f"extrinsics rotation is not a rotation matrix: {list(extrinsics.rotation)}") from None
        return Transform.from_rt(u @ vt, t)


def _rs_distort(coeffs: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """librealsense's projection for ``modified_brown_conrady`` and ``inverse_brown_conrady``.

    Undistorted -> distorted normalised coordinates ``(N, 2)``: the radial factor first, then the
    tangential terms on the radially distorted point, with ``r2`` of the undistorted point
    (``rs2_project_point_to_pixel`` in rsutil.h of librealsense 2.5x, which treats both models alike;
    its deprojection inverts this map iteratively)."""
    c = coeffs
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    f = 1 + c[0] * r2 + c[1] * r2 * r2 + c[4] * r2 * r2 * r2
    x, y = x * f, y * f
    return np.stack([x + 2 * c[2] * x * y + c[3] * (r2 + 2 * x * x),
                     y + 2 * c[3] * x * y + c[2] * (r2 + 2 * y * y)], axis=1)


def fit_opencv_distortion(undistorted: np.ndarray, distorted: np.ndarray) -> np.ndarray:
    """Least-squares OpenCV coefficients ``(k1, k2, p1, p2, k3)`` mapping ``undistorted`` to ``distorted``.

    Both ``(N, 2)`` normalised coordinates. OpenCV's forward model is linear in its five
    coefficients, so this is one linear solve."""
    x, y = undistorted[:, 0], undistorted[:, 1]
    r2 = x * x + y * y
    ax = np.stack([x * r2, x * r2 ** 2, 2 * x * y, r2 + 2 * x * x, x * r2 ** 3], axis=1)
    ay = np.stack([y * r2, y * r2 ** 2, r2 + 2 * y * y, 2 * x * y, y * r2 ** 3], axis=1)
    A = np.concatenate([ax, ay])
    b = np.concatenate([distorted[:, 0] - x, distorted[:, 1] - y])
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    k1, k2, p1, p2, k3 = sol
    return np.array([k1, k2, p1, p2, k3])


def fit_opencv_rational(undistorted: np.ndarray, distorted: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Least-squares OpenCV rational coefficients ``(k1, k2, p1, p2, k3, k4, k5, k6)`` (non-linear, from ``start``)."""
    from scipy.optimize import least_squares

    def residual(c: np.ndarray) -> np.ndarray:
        K = Intrinsics(2, 2, 1.0, 1.0, 0.0, 0.0, "opencv", tuple(c))
        return (K.distort(undistorted) - distorted).ravel()

    x0 = np.concatenate([np.asarray(start, dtype=np.float64)[:5], np.zeros(3)])
    return least_squares(residual, x0, method="lm", xtol=1e-15, ftol=1e-15).x


@dataclass(frozen=True)
class IntrinsicsConversion:
    """An SDK camera model converted to ours, and how exactly."""

    intrinsics: Intrinsics
    sdk_model: str
    exact: bool
    fit_error_px: float = 0.0


def intrinsics_from_rs(intr, *, what: str = "stream") -> IntrinsicsConversion:
    """``rs.intrinsics`` to :class:`Intrinsics` (pixel centres at integer coordinates in both).

    ``brown_conrady`` and ``none`` convert exactly; ``inverse_brown_conrady`` and
    ``modified_brown_conrady`` with non-zero coefficients are fitted (see the module docstring)."""
    model = str(intr.model).split(".")[-1]
    w, h = int(intr.width), int(intr.height)
    fx, fy, cx, cy = f32(intr.fx), f32(intr.fy), f32(intr.ppx), f32(intr.ppy)
    coeffs = np.array([f32(c) for c in intr.coeffs], dtype=np.float64)
    if model == "none" or not np.any(coeffs):
        return IntrinsicsConversion(Intrinsics(w, h, fx, fy, cx, cy), model, True)
    if model == "brown_conrady":
        return IntrinsicsConversion(Intrinsics(w, h, fx, fy, cx, cy, "opencv", tuple(coeffs[:5])), model, True)
    if model in ("inverse_brown_conrady", "modified_brown_conrady"):
        v, u = np.mgrid[0:h:8, 0:w:8]
        uv = np.stack([u.ravel(), v.ravel()], axis=1).astype(np.float64)
        # undistorted points whose images cover the picture (OpenCV's model is close enough to invert)
        approx = Intrinsics(w, h, fx, fy, cx, cy, "opencv", tuple(coeffs[:5]))
        undistorted = approx.pixel_to_normalized(uv)
        distorted = _rs_distort(coeffs, undistorted)
        fitted = fit_opencv_distortion(undistorted, distorted)
        K = Intrinsics(w, h, fx, fy, cx, cy, "opencv", tuple(float(c) for c in fitted))
        fit_err = float((np.abs(K.distort(undistorted) - distorted) * np.array([fx, fy])).max())
        if fit_err > MAX_FIT_ERROR_PX:  # refine with the rational model (8 coefficients)
            K8 = Intrinsics(w, h, fx, fy, cx, cy, "opencv",
                            tuple(float(c) for c in fit_opencv_rational(undistorted, distorted, fitted)))
            err8 = float((np.abs(K8.distort(undistorted) - distorted) * np.array([fx, fy])).max())
            if err8 < fit_err:
                K, fit_err = K8, err8
        if fit_err > MAX_FIT_ERROR_PX:
            raise CalibrationError(f"{what}: distortion model {model} {coeffs.tolist()} has no OpenCV equivalent "
                                   f"(best fit is off by {fit_err:.3f} px)")
        return IntrinsicsConversion(K, model, False, fit_err)
    raise CalibrationError(f"{what}: distortion model {model} (fisheye) is not supported")


# ============================================================================ the frame source
@dataclass(frozen=True)
class _Selected:
    name: str
    profile: Any          # rs.video_stream_profile
    sensor: Any           # rs.sensor
    description: StreamDescription
    sdk_format: Any


_STOP = object()


class RealSenseSource:
    """Streams of one RealSense device (live or a playback device) as :class:`Frame` objects.

    Args:
        device: an ``rs.device`` (live, or ``ctx.load_device(path)`` for a recording).
        requests: stream name (``"depth"``, ``"color"``, ``"ir"``, ``"ir2"``) -> settings or None
            (= whatever the device/recording offers, preferring 640x480 @ 30 fps for live devices).
        label: how error messages name the sensor.
        blocking: the SDK callback waits when ``queue_size`` frames are waiting (playback: no frame is
            ever dropped, the recording is read as fast as it is consumed); live devices use a
            non-blocking unbounded queue (the SDK thread must never wait).
        host_time: frame -> host µs (default: :func:`host_clock_us` at arrival).
    """

    def __init__(self, device, requests: Mapping[str, StreamSettings | None], *, label: str, blocking: bool = False,
                 queue_size: int = 8, host_time: Callable[[Any], int] | None = None,
                 error: type[Exception] = DeviceError) -> None:
        self.device, self.label, self.blocking, self._error = device, label, blocking, error
        self._queue: queue.Queue = queue.Queue(maxsize=queue_size if blocking else 0)
        self._host_time = host_time
        self._failure: str | None = None
        self._started: list = []
        self._closed = threading.Event()
        self.notes: dict[str, Any] = {}
        self.selected = self._select(requests)
        self.description = self._describe()

    # -- description ----------------------------------------------------------------------
    def _info(self, obj, field_name: str) -> str | None:
        key = getattr(rs.camera_info, field_name)
        return obj.get_info(key) if obj.supports(key) else None

    def _select(self, requests: Mapping[str, StreamSettings | None]) -> dict[str, _Selected]:
        sensors = list(self.device.query_sensors())
        chosen: dict[str, _Selected] = {}
        for name, want in requests.items():
            if name not in STREAM_KINDS:
                raise self._error(f"{self.label}: unknown RealSense stream {name!r} (expected one of {', '.join(STREAM_KINDS)})")
            stype, index = STREAM_KINDS[name]
            kind = _STREAM_TYPE_NAME[name]
            best = None
            for sensor in sensors:
                for p in sensor.get_stream_profiles():
                    if p.stream_type() != stype or (index is not None and p.stream_index() != index):
                        continue
                    if p.format() not in _FORMATS[kind] or not p.is_video_stream_profile():
                        continue
                    v = p.as_video_stream_profile()
                    if want is not None and ((want.width and v.width() != want.width)
                                             or (want.height and v.height() != want.height)
                                             or (want.fps and abs(v.fps() - want.fps) > 1e-6)):
                        continue
                    score = (_FORMATS[kind].index(p.format()),
                             0 if (want is None and (v.width(), v.height(), v.fps()) == (640, 480, 30)) else 1,
                             0 if p.is_default() else 1)
                    if best is None or score < best[0]:
                        best = (score, sensor, v)
            if best is None:
                if want is None:
                    continue
                asked = f"{want.width or '*'}x{want.height or '*'} @ {want.fps or '*'} fps"
                raise self._error(f"{self.label}: the device has no {name} stream {asked}")
            _, sensor, v = best
            desc = self._stream_description(name, kind, sensor, v, want.encoding if want is not None else None)
            chosen[name] = _Selected(name, v, sensor, desc, v.format())
        return chosen

    def _stream_description(self, name: str, kind: str, sensor, v, encoding: str | None = None) -> StreamDescription:
        conv = intrinsics_from_rs(v.get_intrinsics(), what=f"{self.label}: {name} intrinsics")
        if not conv.exact:
            self.notes.setdefault("intrinsics_fitted", {})[name] = {
                "sdk_model": conv.sdk_model, "sdk_coeffs": [f32(c) for c in v.get_intrinsics().coeffs],
                "max_error_px": round(conv.fit_error_px, 6)}
        unit = None
        if kind == "depth":
            if not sensor.is_depth_sensor():
                raise self._error(f"{self.label}: the depth stream's sensor reports no depth scale")
            unit = f32(sensor.as_depth_sensor().get_depth_scale())
            if not unit > 0:
                raise self._error(f"{self.label}: depth scale {unit} is not positive")
        encoding = encoding or ("png" if kind == "color" else "png16")  # the rig may ask for jpeg colour
        return StreamDescription(name=name, type=kind, width=v.width(), height=v.height(), fps=float(v.fps()),
                                 encoding=encoding, intrinsics=conv.intrinsics, depth_unit_m=unit)

    def _describe(self) -> SensorDescription:
        T = None
        if "depth" in self.selected and "color" in self.selected:
            T = transform_from_rs(self.selected["color"].profile.get_extrinsics_to(self.selected["depth"].profile))
        clock: dict[str, Any] = {}
        for s in {id(x.sensor): x.sensor for x in self.selected.values()}.values():
            if s.supports(rs.option.global_time_enabled):
                clock[f"global_time_enabled.{self._info(s, 'name') or 'sensor'}"] = bool(
                    s.get_option(rs.option.global_time_enabled))
        model = self._info(self.device, "name") or "Intel RealSense"
        if not model.lower().startswith("intel"):
            model = f"Intel RealSense {model}" if "realsense" not in model.lower() else model
        extras = {k: v for k in ("product_line", "product_id", "usb_type_descriptor", "recommended_firmware_version")
                  if (v := self._info(self.device, k))}
        if extras:
            self.notes["device_info"] = extras
        return SensorDescription(model=model, serial=self._info(self.device, "serial_number") or "unknown",
                                 streams={n: s.description for n, s in self.selected.items()},
                                 firmware=self._info(self.device, "firmware_version"), technology="stereo",
                                 T_depth_color=T, clock=clock)

    # -- streaming ------------------------------------------------------------------------
    def _name_of(self, frame) -> str | None:
        p = frame.get_profile()
        for name, sel in self.selected.items():
            if p.unique_id() == sel.profile.unique_id():
                return name
        return None

    def _convert(self, frame) -> Frame | None:
        name = self._name_of(frame)
        if name is None:
            return None
        sel = self.selected[name]
        data = np.asanyarray(frame.get_data())
        fmt = sel.sdk_format
        if fmt in (rs.format.rgb8, rs.format.z16, rs.format.y16):
            image = data.copy()
        elif fmt == rs.format.bgr8:
            image = cv2.cvtColor(data, cv2.COLOR_BGR2RGB)
        elif fmt == rs.format.rgba8:
            image = np.ascontiguousarray(data[..., :3])
        elif fmt == rs.format.bgra8:
            image = cv2.cvtColor(data, cv2.COLOR_BGRA2RGB)
        elif fmt in (rs.format.yuyv, rs.format.uyvy):
            raw = np.frombuffer(data.tobytes(), np.uint8).reshape(sel.description.height, sel.description.width, 2)
            image = cv2.cvtColor(raw, cv2.COLOR_YUV2RGB_YUYV if fmt == rs.format.yuyv else cv2.COLOR_YUV2RGB_UYVY)
        elif fmt == rs.format.y8:
            image = data.astype(np.uint16)
        else:  # pragma: no cover - _select only picks the formats above
            raise self._error(f"{self.label}: unsupported pixel format {fmt}")
        metadata = {n: int(frame.get_frame_metadata(m)) for n, m in _METADATA if frame.supports_frame_metadata(m)}
        host = self._host_time(frame) if self._host_time else host_clock_us()
        domain = str(frame.get_frame_timestamp_domain()).split(".")[-1]
        return Frame(stream=name, frame_number=int(frame.get_frame_number()),
                     device_timestamp_us=timestamp_ms_to_us(frame.get_timestamp()), clock_domain=domain,
                     host_timestamp_us=int(host), image=image, metadata=metadata)

    def _callback(self, frame) -> None:
        if self._closed.is_set():
            return
        try:
            item = self._convert(frame)
        except Exception as exc:  # never raise into the SDK thread
            self._failure = self._failure or f"{self.label}: cannot read a frame: {exc}"
            item = None
        if item is None:
            return
        while not self._closed.is_set():
            try:
                self._queue.put(item, timeout=0.1)
                return
            except queue.Full:
                continue

    def start(self) -> None:
        """Open the selected profiles on their sensors and start them, all with one callback."""
        by_sensor: dict[int, tuple[Any, list]] = {}
        for sel in self.selected.values():
            by_sensor.setdefault(id(sel.sensor), (sel.sensor, []))[1].append(sel.profile)
        try:
            for sensor, profiles in by_sensor.values():
                sensor.open(profiles if len(profiles) > 1 else profiles[0])
                sensor.start(self._callback)
                self._started.append(sensor)
        except RuntimeError as exc:
            self.stop()
            raise self._error(f"{self.label}: cannot start streaming: {exc}") from None

    def get(self, timeout_s: float) -> Frame | None | object:
        """Next frame, ``None`` after ``timeout_s``, or :data:`_STOP` once :meth:`finish` was called and all is read."""
        if self._failure:
            raise self._error(self._failure)
        try:
            return self._queue.get(timeout=timeout_s)
        except queue.Empty:
            return None

    def finish(self) -> None:
        """Stop the sensors (delivering what they hold), then queue the end marker."""
        self.stop()
        self._put_stop()

    def _put_stop(self) -> None:
        while True:
            try:
                self._queue.put(_STOP, timeout=0.1)
                return
            except queue.Full:
                if self._closed.is_set():
                    return

    def stop(self) -> None:
        for sensor in self._started:
            for call in (sensor.stop, sensor.close):
                try:
                    call()
                except RuntimeError:
                    pass
        self._started = []

    def close(self) -> None:
        """Stop at once, discarding queued frames (ends a blocked :meth:`get` with the end marker)."""
        self._closed.set()
        self.stop()
        while True:
            try:
                self._queue.get_nowait()
            except queue.Empty:
                break
        self._put_stop()


# ============================================================================ recordings (.db3)
_SQLITE_MAGIC = b"SQLite format 3\x00"


def _topic_stream(name: str) -> tuple[Any, int] | None:
    """``/device_0/sensor_1/Color_0/image/data`` -> (rs.stream.color, 0)."""
    parts = name.strip("/").split("/")
    if len(parts) >= 5 and parts[3] == "image" and parts[4].startswith("data"):
        kind, _, index = parts[2].rpartition("_")
        if kind in _TOPIC_STREAM and index.isdigit():
            return _TOPIC_STREAM[kind], int(index)
    return None


def recorded_frame_counts(path: str | Path) -> dict[tuple[Any, int], int]:
    """Image messages per (SDK stream, index) in a ROS2 ``.db3`` recording (read with sqlite3).

    Raises :class:`SessionFormatError` (one line) when the file is not a complete SQLite database
    with the ROS2 bag tables."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            head = f.read(len(_SQLITE_MAGIC))
    except OSError as exc:
        raise SessionFormatError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if head != _SQLITE_MAGIC:
        what = ("empty file" if not head else
                "a ROS1 .bag of an older librealsense; record with librealsense 2.59, which writes .db3"
                if head.startswith(b"#ROSBAG") else "not an SQLite database")
        raise SessionFormatError(f"{path}: not a RealSense .db3 recording ({what})")
    try:
        con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        try:
            check = con.execute("PRAGMA quick_check").fetchall()
            if check != [("ok",)]:
                lines = [ln.strip() for row in check for ln in str(row[0]).splitlines()
                         if ln.strip() and not ln.startswith("***")]
                raise SessionFormatError(f"{path}: corrupt or truncated recording (SQLite integrity check: "
                                         f"{lines[0] if lines else 'failed'}; {len(lines)} problem(s))")
            tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
            if not {"topics", "messages"} <= tables:
                raise SessionFormatError(f"{path}: not a ROS2 bag (no 'topics'/'messages' tables)")
            rows = con.execute("SELECT t.name, COUNT(m.id) FROM topics t LEFT JOIN messages m ON m.topic_id = t.id "
                               "GROUP BY t.id").fetchall()
        finally:
            con.close()
    except sqlite3.DatabaseError as exc:
        raise SessionFormatError(f"{path}: corrupt or truncated recording (SQLite: {exc})") from None
    counts: dict[tuple[Any, int], int] = Counter()
    for name, n in rows:
        key = _topic_stream(name)
        if key is not None:
            counts[key] += n
    return dict(counts)


class RealSenseRecording:
    """A ``.db3`` recording opened through the SDK's playback device (not real time: every frame).

    Use :meth:`frames` once; it checks at the end that the SDK delivered as many frames per
    stream as the file holds. Host timestamps: each frame's ``time_of_arrival`` metadata (ms of the
    recording host's clock) when every frame has it, else its device timestamp (see
    :attr:`host_source`)."""

    def __init__(self, path: str | Path, *, streams: tuple[str, ...] | None = None) -> None:
        self.path = Path(path)
        self.expected = recorded_frame_counts(self.path)
        self._ctx = rs.context()
        try:
            self.device = self._ctx.load_device(str(self.path))
        except RuntimeError as exc:
            raise SessionFormatError(f"{self.path}: not a readable RealSense recording ({_one_line(exc)})") from None
        self.playback = self.device.as_playback()
        self.playback.set_real_time(False)
        offered = set()
        for s in self.device.query_sensors():
            for p in s.get_stream_profiles():
                for name, (stype, index) in STREAM_KINDS.items():
                    if p.stream_type() == stype and (index is None or p.stream_index() == index):
                        offered.add(name)
        if "depth" not in offered:
            raise SessionFormatError(f"{self.path}: the recording has no depth stream")
        wanted = [n for n in (streams or STREAM_KINDS) if n in offered]
        self.host_source = "time_of_arrival"
        self.source = RealSenseSource(self.device, {n: None for n in wanted}, label=str(self.path), blocking=True,
                                      host_time=self._host_time, error=SessionFormatError)
        self.description = self.source.description
        self.notes = self.source.notes

    @staticmethod
    def _host_time(frame) -> int:
        m = rs.frame_metadata_value.time_of_arrival
        return int(frame.get_frame_metadata(m)) * 1000 if frame.supports_frame_metadata(m) else -1

    def expected_count(self, stream: str) -> int:
        sel = self.source.selected[stream]
        return self.expected.get((sel.profile.stream_type(), sel.profile.stream_index()), 0)

    def frames(self, *, timeout_s: float = 30.0) -> Iterator[Frame]:
        """Every frame of the selected streams in delivery order (per stream: recorded order)."""
        stopped = threading.Event()

        def on_status(status) -> None:
            if status == rs.playback_status.stopped:
                stopped.set()

        self.playback.set_status_changed_callback(on_status)
        self.playback.pause()  # start every sensor before the first frame is read
        self.source.start()
        self.playback.resume()

        def finisher() -> None:
            stopped.wait()
            self.source.finish()

        threading.Thread(target=finisher, name="realsense-playback-end", daemon=True).start()
        delivered: Counter = Counter()
        use_toa: bool | None = None
        try:
            while True:
                item = self.source.get(timeout_s)
                if item is None:
                    raise SessionFormatError(f"{self.path}: the SDK delivered no frame for {timeout_s:.0f} s "
                                             f"(stuck playback; {sum(delivered.values())} frames read)")
                if item is _STOP:
                    break
                if use_toa is None:
                    use_toa = item.host_timestamp_us >= 0
                    self.host_source = "time_of_arrival" if use_toa else "device_timestamp"
                if not use_toa or item.host_timestamp_us < 0:
                    if use_toa:
                        raise SessionFormatError(f"{self.path}: frame {item.frame_number} of {item.stream} has no "
                                                 "time_of_arrival metadata but earlier frames do")
                    item = replace(item, host_timestamp_us=item.device_timestamp_us)
                delivered[item.stream] += 1
                yield item
        finally:
            self.source.close()
        for name in self.source.selected:
            want = self.expected_count(name)
            if delivered[name] != want:
                raise SessionFormatError(f"{self.path}: the SDK delivered {delivered[name]} of the {want} recorded "
                                         f"{name} frames (corrupt recording?)")

    def close(self) -> None:
        self.source.close()


def open_recording(path: str | Path, *, streams: tuple[str, ...] | None = None) -> RealSenseRecording:
    """Open a RealSense ``.db3`` recording for reading every frame (see :class:`RealSenseRecording`)."""
    return RealSenseRecording(path, streams=streams)


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text[:300]


# ============================================================================ the live driver
@register
class RealSenseDriver(Driver):
    """A live Intel RealSense camera (D400 family and others the SDK supports).

    With ``options.file`` it plays a ``.db3`` recording in real time instead, through the same
    code (for rigs without the camera, and for testing this driver without hardware); ``serial``
    must then be the recording's serial or ``"*"``, and sync/options are not applied."""

    name = "realsense"
    description = "Intel RealSense depth cameras (pyrealsense2): depth, colour, infrared with per-frame metadata"

    def __init__(self, config: SensorConfig) -> None:
        super().__init__(config)
        self._source: RealSenseSource | None = None
        self._ctx = None
        self._playback = None
        self._done = False

    @classmethod
    def enumerate(cls) -> list[DeviceInfo]:
        out = []
        for dev in rs.context().query_devices():
            def info(key):
                k = getattr(rs.camera_info, key)
                return dev.get_info(k) if dev.supports(k) else None
            details = {k: v for k in ("product_line", "product_id", "usb_type_descriptor", "physical_port",
                                      "camera_locked") if (v := info(k))}
            out.append(DeviceInfo(driver="realsense", serial=info("serial_number") or "?",
                                  model=info("name") or "Intel RealSense", firmware=info("firmware_version"),
                                  details=details))
        return out

    @classmethod
    def check_config(cls, config: SensorConfig) -> None:
        for name, st in config.streams.items():
            if name not in STREAM_KINDS:
                raise RigError(f"sensor {config.label}: RealSense streams are {', '.join(STREAM_KINDS)}, not {name!r}")
            if st.type != _STREAM_TYPE_NAME[name]:
                raise RigError(f"sensor {config.label}: stream {name!r} must have type {_STREAM_TYPE_NAME[name]!r}")
        for key, value in config.sync.items():
            if key not in SYNC_OPTIONS:
                raise RigError(f"sensor {config.label}: unknown RealSense sync setting {key!r} "
                               f"(known: {', '.join(SYNC_OPTIONS)})")
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise RigError(f"sensor {config.label}: sync.{key} must be a number, got {value!r}")
        if "inter_cam_sync_mode" in config.sync and not 0 <= config.sync["inter_cam_sync_mode"] <= 260:
            raise RigError(f"sensor {config.label}: sync.inter_cam_sync_mode must be 0-260 "
                           f"(0 default, 1 master, 2 slave, 3 full slave), got {config.sync['inter_cam_sync_mode']}")
        for key, value in config.options.items():
            if key == "file":
                if not isinstance(value, str):
                    raise RigError(f"sensor {config.label}: options.file must be the path of a .db3 recording")
            elif key == "global_time":
                if not isinstance(value, bool):
                    raise RigError(f"sensor {config.label}: options.global_time must be true or false")
            elif not hasattr(rs.option, key):
                raise RigError(f"sensor {config.label}: unknown RealSense option {key!r}")
            elif isinstance(value, bool) or not isinstance(value, (int, float)):
                raise RigError(f"sensor {config.label}: options.{key} must be a number, got {value!r}")

    def _set_option(self, sensor, key: str, value: float) -> None:
        opt = getattr(rs.option, key)
        if not sensor.supports(opt):
            raise DeviceError(f"{self.config.label}: the device does not support {key}")
        try:
            sensor.set_option(opt, float(value))
        except RuntimeError as exc:
            raise DeviceError(f"{self.config.label}: cannot set {key} = {value}: {_one_line(exc)}") from None

    def _playback_device(self, path: str):
        """``options.file``: a recording played in real time as if it were the camera (sync not applied)."""
        try:
            recorded_frame_counts(path)
            device = self._ctx.load_device(path)
        except (SessionFormatError, RuntimeError) as exc:
            raise DeviceError(f"{self.config.label}: cannot play {path}: {_one_line(exc)}") from None
        serial = device.get_info(rs.camera_info.serial_number) if device.supports(rs.camera_info.serial_number) else "?"
        if self.config.serial not in ("*", serial):
            raise DeviceError(f"{self.config.label}: recording {path} is of camera {serial}, not {self.config.serial}")
        playback = device.as_playback()
        playback.set_real_time(True)
        playback.pause()

        def on_status(status) -> None:  # the SDK's thread must not stop its own sensors: hand it over
            if status == rs.playback_status.stopped and self._source is not None:
                threading.Thread(target=self._source.finish, name="realsense-playback-end", daemon=True).start()

        playback.set_status_changed_callback(on_status)
        self._playback = playback
        return device

    def open(self) -> SensorDescription:
        self.check_config(self.config)
        self._ctx = rs.context()
        options = dict(self.config.options)
        if "file" in options:
            device = self._playback_device(options.pop("file"))
        else:
            devices = list(self._ctx.query_devices())
            serials = [d.get_info(rs.camera_info.serial_number) for d in devices]
            if self.config.serial not in serials:
                seen = ", ".join(serials) if serials else "none"
                raise DeviceError(f"{self.config.label}: no RealSense camera with serial {self.config.serial} "
                                  f"is connected (connected: {seen})")
            device = devices[serials.index(self.config.serial)]
        depth_sensor = next((s for s in device.query_sensors() if s.is_depth_sensor()), None)
        if self._playback is not None:  # a recording: its options and sync are what was recorded
            options, sync = {}, {}
        else:
            sync = self.config.sync
        for key, value in sync.items():
            if depth_sensor is None:
                raise DeviceError(f"{self.config.label}: no depth sensor to apply sync.{key} to")
            self._set_option(depth_sensor, key, value)
        for key, value in options.items():
            if key == "global_time":
                for s in device.query_sensors():
                    if s.supports(rs.option.global_time_enabled):
                        s.set_option(rs.option.global_time_enabled, 1.0 if value else 0.0)
            elif depth_sensor is not None:
                self._set_option(depth_sensor, key, value)
        requests = dict(self.config.streams) or {"depth": None, "color": None}
        self._source = RealSenseSource(device, requests, label=self.config.label, blocking=False)
        desc = self._source.description
        clock = dict(desc.clock)
        if "inter_cam_sync_mode" in sync:
            clock["inter_cam_sync_mode"] = sync["inter_cam_sync_mode"]
        if self._playback is not None:
            clock["played_from"] = str(Path(self.config.options["file"]).resolve())
        desc = replace(desc, clock=clock)
        self._source.start()
        if self._playback is not None:
            self._playback.resume()
        return desc

    def read(self, *, timeout_s: float) -> list[Frame] | None:
        if self._done or self._source is None:
            return None
        first = self._source.get(timeout_s)
        if first is None:
            return []
        out = []
        item = first
        while True:
            if item is _STOP:
                self._done = True
                return out or None
            out.append(item)
            item = self._source.get(0)
            if item is None:
                return out

    def close(self) -> None:
        if self._source is not None:
            self._source.close()
