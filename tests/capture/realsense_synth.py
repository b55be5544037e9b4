"""Synthetic RealSense recordings for tests: ``rs.software_device`` frames recorded by ``rs.recorder``.

Everything goes through the real SDK: a software device with a depth sensor (z16, with a
``depth_units`` option) and a colour sensor (rgb8), factory-style intrinsics and depth-to-colour
extrinsics, device info (name, serial, firmware), frames with chosen frame numbers, timestamps
(ms as double), timestamp domains and per-frame metadata; ``rs.recorder`` writes a ROS2 ``.db3``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyrealsense2 as rs


@dataclass
class SynthSpec:
    """What one synthetic camera sends (the test compares the import against it)."""

    name: str = "Intel RealSense D415"
    serial: str = "000000000001"
    firmware: str = "5.16.0.1"
    depth_size: tuple[int, int] = (640, 480)
    color_size: tuple[int, int] = (640, 480)
    # fx, fy, ppx, ppy (float32-exact decimals), model, coeffs
    depth_intrinsics: tuple = (601.25, 600.75, 319.5, 238.25, "brown_conrady", (0.125, -0.25, 0.001, -0.002, 0.0625))
    color_intrinsics: tuple = (615.5, 615.25, 322.75, 241.5, "none", (0.0, 0.0, 0.0, 0.0, 0.0))
    depth_units: float = 0.001
    # depth -> colour extrinsics (SDK convention): rotation about y by `angle` rad, translation metres
    angle: float = 0.01
    translation: tuple = (0.015, -0.0005, 0.00025)
    fps: int = 30
    depth_frame_numbers: list[int] = field(default_factory=lambda: [100, 101, 102, 104, 105])
    color_frame_numbers: list[int] = field(default_factory=lambda: [7, 8, 9, 10, 11])
    t0_us: int = 1_234_567_890
    period_us: int = 33_333
    domain: str = "hardware_clock"
    with_color: bool = True
    with_depth: bool = True
    time_of_arrival_ms: int | None = 1_700_000_000_000

    def depth_timestamps_us(self) -> list[int]:
        base = self.depth_frame_numbers[0]
        return [self.t0_us + (n - base) * self.period_us for n in self.depth_frame_numbers]

    def color_timestamps_us(self) -> list[int]:
        return [self.t0_us + 250 + i * self.period_us for i in range(len(self.color_frame_numbers))]

    def depth_image(self, i: int) -> np.ndarray:
        w, h = self.depth_size
        rng = np.random.default_rng(1000 + i)
        img = rng.integers(300, 4000, (h, w), dtype=np.uint16)
        img[rng.random((h, w)) < 0.2] = 0
        return img

    def color_image(self, i: int) -> np.ndarray:
        w, h = self.color_size
        return np.random.default_rng(2000 + i).integers(0, 256, (h, w, 3), dtype=np.uint8)

    def rotation_matrix(self) -> np.ndarray:
        c, s = np.cos(self.angle), np.sin(self.angle)
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=np.float32).astype(np.float64)


def _intrinsics(w: int, h: int, spec: tuple) -> rs.intrinsics:
    fx, fy, ppx, ppy, model, coeffs = spec
    i = rs.intrinsics()
    i.width, i.height, i.fx, i.fy, i.ppx, i.ppy = w, h, fx, fy, ppx, ppy
    i.model = getattr(rs.distortion, model)
    i.coeffs = list(coeffs)
    return i


def record_synthetic(path: str | Path, spec: SynthSpec) -> Path:
    """Write ``spec`` as a real ``.db3`` recording through ``rs.software_device`` + ``rs.recorder``."""
    path = Path(path)
    dev = rs.software_device()
    dev.register_info(rs.camera_info.name, spec.name)
    dev.register_info(rs.camera_info.serial_number, spec.serial)
    dev.register_info(rs.camera_info.firmware_version, spec.firmware)
    sensors: list = []
    depth_profile = None
    if spec.with_depth:
        depth_sensor = dev.add_sensor("Stereo Module")
        vs = rs.video_stream()
        vs.type, vs.index, vs.uid = rs.stream.depth, 0, 0
        vs.width, vs.height = spec.depth_size
        vs.fps, vs.bpp, vs.fmt = spec.fps, 2, rs.format.z16
        vs.intrinsics = _intrinsics(*spec.depth_size, spec.depth_intrinsics)
        depth_profile = depth_sensor.add_video_stream(vs)
        depth_sensor.add_read_only_option(rs.option.depth_units, spec.depth_units)
        sensors.append((depth_sensor, depth_profile, 0))
    if spec.with_color:
        color_sensor = dev.add_sensor("RGB Camera")
        cs = rs.video_stream()
        cs.type, cs.index, cs.uid = rs.stream.color, 0, 1
        cs.width, cs.height = spec.color_size
        cs.fps, cs.bpp, cs.fmt = spec.fps, 3, rs.format.rgb8
        cs.intrinsics = _intrinsics(*spec.color_size, spec.color_intrinsics)
        color_profile = color_sensor.add_video_stream(cs)
        if depth_profile is not None:
            ex = rs.extrinsics()
            ex.rotation = [float(v) for v in spec.rotation_matrix().T.ravel()]  # column-major
            ex.translation = list(spec.translation)
            depth_profile.register_extrinsics_to(color_profile, ex)
        sensors.append((color_sensor, color_profile, 1))
    recorder = rs.recorder(str(path), dev)
    for s, p, _ in sensors:
        s.open(p)
        s.start(lambda f: None)
    domain = getattr(rs.timestamp_domain, spec.domain)
    events = []
    if spec.with_depth:
        events += [(t, 0, i) for i, t in enumerate(spec.depth_timestamps_us())]
    if spec.with_color:
        events += [(t, 1, i) for i, t in enumerate(spec.color_timestamps_us())]
    by_kind = {kind: (s, p) for s, p, kind in sensors}
    for t_us, which, i in sorted(events):
        sensor, profile = by_kind[which]
        img = spec.depth_image(i) if which == 0 else spec.color_image(i)
        number = (spec.depth_frame_numbers if which == 0 else spec.color_frame_numbers)[i]
        sensor.set_metadata(rs.frame_metadata_value.frame_counter, number)
        sensor.set_metadata(rs.frame_metadata_value.sensor_timestamp, t_us - 500)
        sensor.set_metadata(rs.frame_metadata_value.frame_timestamp, t_us)
        if spec.time_of_arrival_ms is not None:
            sensor.set_metadata(rs.frame_metadata_value.time_of_arrival,
                                spec.time_of_arrival_ms + (t_us - spec.t0_us) // 1000)
        f = rs.software_video_frame()
        f.pixels = img
        f.bpp = 2 if which == 0 else 3
        f.stride = img.shape[1] * f.bpp
        f.timestamp = t_us / 1000.0
        f.domain = domain
        f.frame_number = number
        f.profile = profile.as_video_stream_profile()
        if which == 0:
            f.depth_units = spec.depth_units
        sensor.on_video_frame(f)
    time.sleep(0.05)
    for s, _, _ in sensors:
        s.stop()
        s.close()
    recorder.pause()
    del recorder
    return path
