"""Azure Kinect DK recordings (the Matroska ``.mkv`` files of ``k4arecorder``), read with PyAV.

The container is demuxed by PyAV (FFmpeg's Matroska reader); this module only interprets what
the Azure Kinect recorder puts in it (``docs: Azure Kinect recording file format``):

* tracks ``COLOR`` (MJPG, or raw NV12/YUY2/BGRA), ``DEPTH`` and ``IR`` (codec FourCC ``b16g``:
  16-bit **big-endian** grayscale; depth in millimetres, 0 = no measurement), ``IMU`` (ignored);
* tags ``K4A_DEPTH_MODE`` (e.g. ``NFOV_UNBINNED``), ``K4A_COLOR_MODE`` (e.g. ``MJPG_720P``),
  ``K4A_DEVICE_SERIAL_NUMBER``, ``K4A_*_FIRMWARE_VERSION``, ``K4A_START_OFFSET_NS``,
  ``K4A_WIRED_SYNC_MODE``, ``K4A_DEPTH_DELAY_NS``;
* the attachment ``calibration.json``: the factory calibration of the whole device.

Timestamps: a block's Matroska time is the device time minus the start offset, so the device
timestamp (µs, the Azure Kinect's device clock) is ``pts + K4A_START_OFFSET_NS / 1000`` exactly as
the Azure Kinect SDK's playback computes it. The recorder writes no frame counter; frame numbers
are ``round((pts - first pts of any video track) / frame period)``, so a gap in them is a dropped
frame and depth, IR and colour of one capture share a number.

Calibration (:func:`parse_calibration`): ``calibration.json`` stores per camera the raw sensor-mode
intrinsics **normalised by the sensor size with pixel (0, 0)'s corner at the origin**, in the order
``cx, cy, fx, fy, k1, k2, k3, k4, k5, k6, codx, cody, p2, p1`` (note p2 before p1), and an ``Rt``
(row-major rotation, translation in **metres**) mapping depth-camera points into that camera. The
mode-specific intrinsics follow the SDK (``transformation_get_mode_specific_camera_calibration``):
scale by the binned sensor size, subtract the crop offset, then subtract 0.5 to put pixel centres at
integer coordinates (OpenCV, our convention). Brown-Conrady is OpenCV's rational model
``k1, k2, p1, p2, k3, k4, k5, k6`` with the same formula, so it converts exactly; the deprecated
Rational6KT model (different tangential terms) and a non-zero centre of distortion are refused.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Iterator

import cv2
import numpy as np

from capture.camera import Intrinsics, Transform
from capture.drivers.base import (DeviceInfo, Driver, Frame, SensorConfig, SensorDescription, StreamDescription,
                                  host_clock_us, register)
from capture.errors import CalibrationError, DeviceError, RigError, SessionFormatError

#: Depth modes: (binned calibration resolution, crop offset, output resolution), from the Azure Kinect SDK.
DEPTH_MODES: dict[str, tuple[tuple[int, int], tuple[int, int], tuple[int, int]]] = {
    "NFOV_2X2BINNED": ((512, 512), (96, 90), (320, 288)),
    "NFOV_UNBINNED": ((1024, 1024), (192, 180), (640, 576)),
    "WFOV_2X2BINNED": ((512, 512), (0, 0), (512, 512)),
    "WFOV_UNBINNED": ((1024, 1024), (0, 0), (1024, 1024)),
    "PASSIVE_IR": ((1024, 1024), (0, 0), (1024, 1024)),
}
#: Legacy names of depth modes written by early recorders.
_LEGACY_DEPTH_MODES = {"NFOV_2X2BINNED": "NFOV_2X2BINNED", "NFOV_UNBINNED": "NFOV_UNBINNED",
                       "WFOV_2X2BINNED": "WFOV_2X2BINNED", "WFOV_UNBINNED": "WFOV_UNBINNED",
                       "PASSIVE_IR": "PASSIVE_IR", "NFOV_2x2BINNED": "NFOV_2X2BINNED",
                       "WFOV_2x2BINNED": "WFOV_2X2BINNED"}
#: Colour resolutions (by output height): (4:3 binned calibration resolution, crop offset, output resolution).
COLOR_MODES: dict[int, tuple[tuple[int, int], tuple[int, int], tuple[int, int]]] = {
    720: ((1280, 960), (0, 120), (1280, 720)),
    1080: ((1920, 1440), (0, 180), (1920, 1080)),
    1440: ((2560, 1920), (0, 240), (2560, 1440)),
    1536: ((2048, 1536), (0, 0), (2048, 1536)),
    2160: ((3840, 2880), (0, 360), (3840, 2160)),
    3072: ((4096, 3072), (0, 0), (4096, 3072)),
}
DEPTH_UNIT_M = 0.001
_FOURCC_FORMATS = {"b16g": "b16g", "MJPG": "mjpeg", "NV12": "nv12", "YUY2": "yuy2", "BGRA": "bgra"}


# ============================================================================ calibration (pure)
@dataclass(frozen=True)
class CameraCalibration:
    """One camera of ``calibration.json`` in its raw, normalised form."""

    purpose: str
    model_type: str
    params: tuple[float, ...]          # cx, cy, fx, fy, k1..k6, codx, cody, p2, p1 (normalised)
    sensor_size: tuple[int, int]       # (width, height) of the calibration images
    R: np.ndarray                      # 3x3, maps depth-camera points into this camera
    t_m: np.ndarray                    # metres
    metric_radius: float

    def intrinsics(self, binned: tuple[int, int], crop: tuple[int, int], out: tuple[int, int]) -> Intrinsics:
        """Mode-specific intrinsics, pixel centres at integer coordinates (see the module docstring)."""
        cx, cy, fx, fy, k1, k2, k3, k4, k5, k6, codx, cody, p2, p1 = self.params[:14]
        if self.model_type != "CALIBRATION_LensDistortionModelBrownConrady":
            raise CalibrationError(f"{self.purpose}: lens model {self.model_type} has no exact OpenCV equivalent "
                                   "(only Brown-Conrady is supported)")
        if codx or cody:
            raise CalibrationError(f"{self.purpose}: a non-zero centre of distortion ({codx}, {cody}) is not supported")
        bw, bh = binned
        px_cx = cx * bw - crop[0] - 0.5
        px_cy = cy * bh - crop[1] - 0.5
        return Intrinsics(int(out[0]), int(out[1]), fx * bw, fy * bh, px_cx, px_cy, "opencv",
                          (k1, k2, p1, p2, k3, k4, k5, k6))

    @property
    def T_cam_depth(self) -> Transform:
        return Transform.from_rt(_orthonormal(self.R), self.t_m)


def _orthonormal(R: np.ndarray) -> np.ndarray:
    """The nearest rotation to ``R`` (the file stores float32-precision matrices)."""
    u, _, vt = np.linalg.svd(R)
    Ro = u @ vt
    if np.abs(Ro - R).max() > 1e-4:
        raise CalibrationError(f"calibration rotation is not a rotation matrix: {R.tolist()}")
    return Ro


@dataclass(frozen=True)
class AzureCalibration:
    """The parsed factory calibration: raw cameras plus the mode-specific results."""

    depth: CameraCalibration
    color: CameraCalibration | None
    serial: str | None
    depth_intrinsics: Intrinsics | None = None
    color_intrinsics: Intrinsics | None = None

    @property
    def T_depth_color(self) -> Transform | None:
        """Maps colour-camera points into the depth camera (metres)."""
        if self.color is None:
            return None
        T_color_depth = self.color.T_cam_depth @ self.depth.T_cam_depth.inverse()
        return T_color_depth.inverse()


def _camera(cam: dict, where: str) -> CameraCalibration:
    try:
        intr = cam["Intrinsics"]
        params = tuple(float(v) for v in intr["ModelParameters"])
        count = int(intr.get("ModelParameterCount", len(params)))
        if count < 14 or len(params) < 14:
            raise CalibrationError(f"{where}: expected 14 model parameters, got {min(count, len(params))}")
        rt = cam["Rt"]
        R = np.array([float(v) for v in rt["Rotation"]], dtype=np.float64).reshape(3, 3)
        t = np.array([float(v) for v in rt["Translation"]], dtype=np.float64).reshape(3)
        return CameraCalibration(purpose=cam.get("Purpose", "?"), model_type=intr["ModelType"], params=params,
                                 sensor_size=(int(cam["SensorWidth"]), int(cam["SensorHeight"])), R=R, t_m=t,
                                 metric_radius=float(cam.get("MetricRadius", 0.0)))
    except (KeyError, TypeError, ValueError) as exc:
        raise CalibrationError(f"{where}: malformed camera entry ({type(exc).__name__}: {exc})") from None


def parse_calibration(text: str | bytes, *, depth_mode: str | None = None,
                      color_size: tuple[int, int] | None = None, where: str = "calibration.json") -> AzureCalibration:
    """Parse an Azure Kinect ``calibration.json``; with a depth mode / colour size, also the mode intrinsics.

    Args:
        text: the JSON text.
        depth_mode: e.g. ``"NFOV_UNBINNED"`` (see :data:`DEPTH_MODES`).
        color_size: ``(width, height)`` of the colour images, e.g. ``(1280, 720)``.
    """
    try:
        data = json.loads(text)
        cams = data["CalibrationInformation"]["Cameras"]
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError) as exc:
        raise CalibrationError(f"{where}: not an Azure Kinect calibration ({type(exc).__name__})") from None
    by_purpose = {c.get("Purpose"): c for c in cams if isinstance(c, dict)}
    if "CALIBRATION_CameraPurposeDepth" not in by_purpose:
        raise CalibrationError(f"{where}: no depth camera in the calibration")
    depth = _camera(by_purpose["CALIBRATION_CameraPurposeDepth"], f"{where}: depth camera")
    color = None
    if "CALIBRATION_CameraPurposePhotoVideo" in by_purpose:
        color = _camera(by_purpose["CALIBRATION_CameraPurposePhotoVideo"], f"{where}: colour camera")
    serial = data["CalibrationInformation"].get("Metadata", {}).get("SerialId")
    depth_K = color_K = None
    if depth_mode is not None:
        mode = _LEGACY_DEPTH_MODES.get(depth_mode, depth_mode)
        if mode not in DEPTH_MODES:
            raise CalibrationError(f"{where}: unknown depth mode {depth_mode!r}")
        if depth.sensor_size != (1024, 1024):
            raise CalibrationError(f"{where}: depth calibration is {depth.sensor_size}, expected 1024x1024")
        depth_K = depth.intrinsics(*DEPTH_MODES[mode])
    if color_size is not None and color is not None:
        color_K = _color_intrinsics(color, color_size, where)
    return AzureCalibration(depth, color, serial, depth_K, color_K)


def _color_intrinsics(color: CameraCalibration, size: tuple[int, int], where: str) -> Intrinsics:
    w, h = color.sensor_size
    cam = color
    if w * 9 // 16 == h:  # legacy 16:9 calibration: re-express it in the 4:3 sensor frame (normalised)
        p = list(color.params)
        bw, bh, crop_y, out_h = 4096, 2304, -384, 3072
        p[0], p[1] = p[0] * bw / 4096, (p[1] * bh - crop_y) / out_h
        p[2], p[3] = p[2] * bw / 4096, p[3] * bh / out_h
        cam = replace(color, params=tuple(p), sensor_size=(4096, 3072))
    elif w * 3 // 4 != h:
        raise CalibrationError(f"{where}: colour calibration size {w}x{h} is neither 4:3 nor 16:9")
    mode = COLOR_MODES.get(int(size[1]))
    if mode is None or mode[2] != tuple(size):
        raise CalibrationError(f"{where}: unknown colour resolution {size[0]}x{size[1]}")
    return cam.intrinsics(*mode)


# ============================================================================ the recording reader
@dataclass
class _Track:
    name: str            # our stream name
    index: int           # PyAV stream index
    codec: str           # b16g, mjpeg, nv12, yuy2, bgra
    width: int
    height: int
    time_base: Any


@dataclass
class AzureKinectRecording:
    """An opened ``.mkv``: description, calibration and a frame iterator (:meth:`frames`)."""

    path: Path
    description: SensorDescription
    calibration: AzureCalibration
    tags: dict[str, str]
    period_us: int
    start_offset_us: int
    tracks: dict[str, _Track] = field(repr=False, default_factory=dict)
    notes: dict[str, Any] = field(default_factory=dict)

    def frames(self) -> Iterator[Frame]:
        """Every frame of the selected tracks, in file order (host timestamp = device timestamp)."""
        import av
        import av.logging

        by_index = {t.index: t for t in self.tracks.values()}
        first_pts: int | None = None
        counts = {name: 0 for name in self.tracks}
        previous, previous_skip = av.logging.get_level(), av.logging.get_skip_repeated()
        av.logging.set_level(av.logging.ERROR)
        av.logging.set_skip_repeated(False)  # PyAV swallows a message identical to the last one logged
        try:
            with av.logging.Capture(True) as logs:
                try:
                    container = av.open(str(self.path))
                except (av.error.FFmpegError, OSError) as exc:
                    raise SessionFormatError(f"{self.path}: not a readable Matroska file ({_one_line(exc)})") from None
                with container:
                    try:
                        packets = container.demux([container.streams[i] for i in sorted(by_index)])
                        for packet in packets:
                            track = by_index.get(packet.stream.index)
                            if track is None or packet.size == 0 or packet.pts is None:
                                continue
                            pts_us = int(round(packet.pts * track.time_base * 1_000_000))
                            if first_pts is None:
                                first_pts = pts_us
                            number = int(round((pts_us - first_pts) / self.period_us))
                            image = self._decode(track, bytes(packet))
                            counts[track.name] += 1
                            device_us = pts_us + self.start_offset_us
                            yield Frame(stream=track.name, frame_number=number, device_timestamp_us=device_us,
                                        clock_domain="device", host_timestamp_us=device_us, image=image)
                    except av.error.FFmpegError as exc:
                        raise SessionFormatError(f"{self.path}: corrupt recording ({_one_line(exc)})") from None
            errors = [m for level, _, m in logs if level <= av.logging.ERROR]
            if errors:
                raise SessionFormatError(f"{self.path}: corrupt or truncated recording "
                                         f"(FFmpeg: {' '.join(errors[0].split())})")
        finally:
            av.logging.set_level(previous)
            av.logging.set_skip_repeated(previous_skip)
        if counts.get("depth", 0) == 0:
            raise SessionFormatError(f"{self.path}: the recording has no depth frames")

    def _decode(self, track: _Track, data: bytes) -> np.ndarray:
        w, h = track.width, track.height
        if track.codec == "b16g":
            if len(data) != w * h * 2:
                raise SessionFormatError(f"{self.path}: truncated {track.name} frame ({len(data)} bytes, "
                                         f"expected {w * h * 2})")
            return np.frombuffer(data, ">u2").reshape(h, w).astype(np.uint16)
        if track.codec == "mjpeg":
            if not data.rstrip(b"\x00").endswith(b"\xff\xd9"):
                raise SessionFormatError(f"{self.path}: truncated colour frame (JPEG without end marker)")
            bgr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
            if bgr is None or bgr.shape[:2] != (h, w):
                raise SessionFormatError(f"{self.path}: undecodable colour frame")
            return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        sizes = {"nv12": w * h * 3 // 2, "yuy2": w * h * 2, "bgra": w * h * 4}
        if len(data) != sizes[track.codec]:
            raise SessionFormatError(f"{self.path}: truncated colour frame ({len(data)} bytes)")
        buf = np.frombuffer(data, np.uint8)
        if track.codec == "nv12":
            return cv2.cvtColor(buf.reshape(h * 3 // 2, w), cv2.COLOR_YUV2RGB_NV12)
        if track.codec == "yuy2":
            return cv2.cvtColor(buf.reshape(h, w, 2), cv2.COLOR_YUV2RGB_YUY2)
        return cv2.cvtColor(buf.reshape(h, w, 4), cv2.COLOR_BGRA2RGB)


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.errno == 5:  # FFmpeg's AVERROR(EIO): it could not parse the start
        return "truncated, or not a Matroska file"
    return " ".join(str(exc).split())[:300]


@dataclass
class _MkvContents:
    """What :func:`_read_container` finds in a recording's container (no frame is decoded)."""

    tags: dict[str, str]                 # K4A_* tags of the file and its tracks
    tracks: dict[str, _Track]            # depth (always), color, ir
    calibration_text: bytes | None       # the calibration.json attachment
    period_ns: int | None                # the first depth packet's duration (Matroska DefaultDuration)


def _track_of(path: Path, s) -> _Track | None:
    """The :class:`_Track` of a PyAV video stream titled COLOR, DEPTH, IR or DEPTH_IR (None for others)."""
    title = (s.metadata or {}).get("title", "")
    if s.type != "video" or title not in ("COLOR", "DEPTH", "IR", "DEPTH_IR"):
        return None
    name = {"COLOR": "color", "DEPTH": "depth", "IR": "ir", "DEPTH_IR": "ir"}[title]
    tag = s.codec_context.codec_tag if s.codec_context is not None else ""
    codec = _FOURCC_FORMATS.get(tag) or ("mjpeg" if s.codec_context and s.codec_context.name == "mjpeg" else None)
    if codec is None or (name != "color" and codec != "b16g"):
        raise SessionFormatError(f"{path}: track {title} has unsupported codec {tag or '?'}")
    return _Track(name=name, index=s.index, codec=codec, width=s.codec_context.width, height=s.codec_context.height,
                  time_base=s.time_base)


def _read_container(path: Path) -> _MkvContents:
    """Tags, tracks, calibration attachment and frame period of a Matroska file (one-line errors)."""
    import av

    try:
        container = av.open(str(path))
    except (av.error.FFmpegError, OSError) as exc:
        raise SessionFormatError(f"{path}: not a readable Matroska file ({_one_line(exc)})") from None
    with container:
        if "matroska" not in container.format.name:
            raise SessionFormatError(f"{path}: not a Matroska file (format {container.format.name})")
        out = _MkvContents({k: str(v) for k, v in container.metadata.items()}, {}, None, None)
        for s in container.streams:
            out.tags.update({k: str(v) for k, v in (s.metadata or {}).items() if k.startswith("K4A_")})
            if s.type == "attachment":
                if s.name == "calibration.json" or "K4A_CALIBRATION_FILE" in (s.metadata or {}):
                    out.calibration_text = bytes(s.data) if s.data is not None else None
            elif (track := _track_of(path, s)) is not None:
                out.tracks[track.name] = track
        if "depth" not in out.tracks:
            raise SessionFormatError(f"{path}: the recording has no depth stream (tracks: "
                                     f"{', '.join(sorted(out.tracks)) or 'none'})")
        for packet in container.demux(container.streams[out.tracks["depth"].index]):
            if packet.duration:
                out.period_ns = int(round(packet.duration * packet.time_base * 1e9))
            break
    return out


def _sensor_description(path: Path, tags: dict[str, str], calib: AzureCalibration, selected: dict[str, _Track], *,
                        fps: float) -> SensorDescription:
    """The session's description of the selected tracks (streams, serial, firmware, clock facts)."""
    descs: dict[str, StreamDescription] = {}
    for name, t in selected.items():
        if name == "color":
            if calib.color_intrinsics is None:
                raise SessionFormatError(f"{path}: colour track but no colour camera in the calibration")
            descs[name] = StreamDescription(name=name, type="color", width=t.width, height=t.height, fps=fps,
                                            encoding="png", intrinsics=calib.color_intrinsics)
        else:
            descs[name] = StreamDescription(name=name, type="depth" if name == "depth" else "ir", width=t.width,
                                            height=t.height, fps=fps, encoding="png16",
                                            intrinsics=calib.depth_intrinsics,
                                            depth_unit_m=DEPTH_UNIT_M if name == "depth" else None)
    firmware = ", ".join(f"{k.split('_')[1].lower()} {tags[k]}" for k in
                         ("K4A_DEPTH_FIRMWARE_VERSION", "K4A_COLOR_FIRMWARE_VERSION") if k in tags) or None
    clock = {"domain": "device", "wired_sync_mode": tags.get("K4A_WIRED_SYNC_MODE", "STANDALONE"),
             "start_offset_us": int(tags.get("K4A_START_OFFSET_NS", "0")) // 1000,
             "depth_delay_off_color_us": int(tags.get("K4A_DEPTH_DELAY_NS", "0")) // 1000}
    if "K4A_SUBORDINATE_DELAY_NS" in tags:
        clock["subordinate_delay_off_master_us"] = int(tags["K4A_SUBORDINATE_DELAY_NS"]) // 1000
    return SensorDescription(model="Azure Kinect DK", serial=tags.get("K4A_DEVICE_SERIAL_NUMBER") or calib.serial or "unknown",
                             streams=descs, firmware=firmware, technology="tof",
                             T_depth_color=calib.T_depth_color if "color" in selected else None, clock=clock)


def open_mkv(path: str | os.PathLike, *, streams: tuple[str, ...] = ("depth", "color", "ir")) -> AzureKinectRecording:
    """Open an Azure Kinect recording; raises :class:`SessionFormatError` (one line) for unusable files.

    Args:
        path: the ``.mkv`` file.
        streams: which of ``depth`` (required), ``color``, ``ir`` to read when present.
    """
    path = Path(path)
    if not path.is_file():
        raise SessionFormatError(f"{path}: no such file" if not path.exists() else f"{path}: not a file")
    mkv = _read_container(path)
    tags, tracks = mkv.tags, mkv.tracks
    if mkv.calibration_text is None:
        raise SessionFormatError(f"{path}: no calibration.json attachment (factory calibration missing)")
    depth_mode = tags.get("K4A_DEPTH_MODE")
    if depth_mode is None:
        raise SessionFormatError(f"{path}: no K4A_DEPTH_MODE tag")
    color_size = (tracks["color"].width, tracks["color"].height) if "color" in tracks else None
    try:
        calib = parse_calibration(mkv.calibration_text, depth_mode=depth_mode, color_size=color_size,
                                  where=f"{path}: calibration.json")
    except CalibrationError as exc:
        raise SessionFormatError(str(exc)) from None
    d = tracks["depth"]
    if (d.width, d.height) != (calib.depth_intrinsics.width, calib.depth_intrinsics.height):
        raise SessionFormatError(f"{path}: depth track is {d.width}x{d.height} but mode {depth_mode} is "
                                 f"{calib.depth_intrinsics.width}x{calib.depth_intrinsics.height}")
    fps = 1e9 / mkv.period_ns if mkv.period_ns else 30.0
    fps = min((5.0, 15.0, 30.0), key=lambda f: abs(f - fps))
    selected = {n: t for n, t in tracks.items() if n in streams or n == "depth"}
    desc = _sensor_description(path, tags, calib, selected, fps=fps)
    notes = {"depth_mode": depth_mode, "color_mode": tags.get("K4A_COLOR_MODE"),
             "metric_radius": {"depth": calib.depth.metric_radius} | (
                 {"color": calib.color.metric_radius} if calib.color else {})}
    return AzureKinectRecording(path=path, description=desc, calibration=calib, tags=tags,
                                period_us=int(round(1e6 / fps)), start_offset_us=desc.clock["start_offset_us"],
                                tracks=selected, notes=notes)


# ============================================================================ driver (recording playback)
@register
class AzureKinectDriver(Driver):
    """Plays an Azure Kinect ``.mkv`` recording as a live source (``options.file``), in real time.

    Live Azure Kinect capture needs Microsoft's Sensor SDK, which is not a dependency: record with
    ``k4arecorder`` and import the file (``depthbench capture import azure-kinect``), or put the file in
    a rig to record it next to live sensors. ``serial`` must match the recording's serial (or be ``"*"``)."""

    name = "azure_kinect"
    description = "Azure Kinect DK recordings (.mkv) played back in real time (live capture: use k4arecorder)"

    def __init__(self, config: SensorConfig) -> None:
        super().__init__(config)
        self._iter: Iterator[Frame] | None = None
        self._closed = False
        self._t0_host: int | None = None
        self._t0_dev: int | None = None
        self._pending: Frame | None = None

    @classmethod
    def check_config(cls, config: SensorConfig) -> None:
        if "file" not in config.options:
            raise RigError(f"sensor {config.label}: the azure_kinect driver plays a recording; set options.file "
                           "to a k4arecorder .mkv (live capture needs the Azure Kinect SDK)")
        unknown = set(config.options) - {"file"}
        if unknown:
            raise RigError(f"sensor {config.label}: unknown azure_kinect option {sorted(unknown)[0]!r}")
        for name in config.streams:
            if name not in ("depth", "color", "ir"):
                raise RigError(f"sensor {config.label}: Azure Kinect streams are depth, color, ir, not {name!r}")

    def open(self) -> SensorDescription:
        self.check_config(self.config)
        try:
            rec = open_mkv(self.config.options["file"], streams=tuple(self.config.streams) or ("depth", "color", "ir"))
        except SessionFormatError as exc:
            raise DeviceError(f"{self.config.label}: {exc}") from None
        if self.config.serial not in ("*", rec.description.serial):
            raise DeviceError(f"{self.config.label}: recording {rec.path} is of device {rec.description.serial}")
        self._iter = rec.frames()
        return rec.description

    def read(self, *, timeout_s: float) -> list[Frame] | None:
        import time

        if self._closed or self._iter is None:
            return None
        deadline = host_clock_us() + int(timeout_s * 1e6)
        out: list[Frame] = []
        while True:
            if self._pending is None:
                try:
                    self._pending = next(self._iter)
                except StopIteration:
                    self._iter = None
                    return out or None
                except SessionFormatError as exc:
                    raise DeviceError(f"{self.config.label}: {exc}") from None
            f = self._pending
            if self._t0_host is None:
                self._t0_host, self._t0_dev = host_clock_us(), f.device_timestamp_us
            due = self._t0_host + (f.device_timestamp_us - self._t0_dev)
            now = host_clock_us()
            if due > now:
                if out or due > deadline:
                    if not out:
                        time.sleep(max(0.0, (deadline - now) / 1e6))
                    return out
                time.sleep((due - now) / 1e6)
            self._pending = None
            out.append(replace(f, host_timestamp_us=host_clock_us()))

    def close(self) -> None:
        self._closed = True
        self._iter = None

    @classmethod
    def enumerate(cls) -> list[DeviceInfo]:
        return []
