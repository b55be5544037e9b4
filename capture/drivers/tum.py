"""TUM RGB-D benchmark folders (Sturm et al., IROS 2012): ``rgb.txt``, ``depth.txt``, ``rgb/``, ``depth/``.

Layout (https://cvg.cit.tum.de/data/datasets/rgbd-dataset/file_formats)::

    DIR/rgb.txt          # comment lines start with '#'; then "timestamp filename" per line
    DIR/depth.txt        # timestamps are seconds as decimals, e.g. 1305031102.175304
    DIR/rgb/1305031102.175304.png     8-bit colour, 640x480
    DIR/depth/1305031102.160407.png   16-bit depth, value / 5000 = metres, 0 = no measurement

Timestamps are parsed from their decimal text (never through a float) into int µs. The depth
images are registered to the colour camera (``T_depth_color`` is the identity) and share its
intrinsics; TUM's default for the Kinect v1 is fx = fy = 525, cx = 319.5, cy = 239.5 (pass
others for the freiburg1/2/3 calibrations). Both timestamp columns of a session carry the TUM
timestamps (the recording PC's clock).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from capture.camera import Intrinsics, Transform
from capture.drivers.base import Frame, SensorDescription, StreamDescription
from capture.errors import SessionFormatError
from capture.session import image_structure_problem

DEFAULT_INTRINSICS = Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)
DEPTH_SCALE = 5000.0   # counts per metre


def parse_timestamp_us(text: str, *, where: str) -> int:
    """``"1305031102.175304"`` (seconds) -> ``1305031102175304`` (int µs), exactly, rounding sub-µs digits."""
    try:
        value = Decimal(text)
    except InvalidOperation:
        raise SessionFormatError(f"{where}: timestamp {text!r} is not a number") from None
    if not value.is_finite() or value < 0:
        raise SessionFormatError(f"{where}: timestamp {text!r} is not a non-negative number")
    return int((value * 1_000_000).to_integral_value())


def parse_list(path: Path) -> list[tuple[int, str]]:
    """Read a TUM list file into ``[(timestamp_us, relative file name), ...]`` in file order."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SessionFormatError(f"{path}: missing (not a TUM RGB-D folder)") from None
    except UnicodeDecodeError:
        raise SessionFormatError(f"{path}: not a text file") from None
    out = []
    for line_no, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.split()
        if len(parts) < 2:
            raise SessionFormatError(f"{path}: line {line_no}: expected 'timestamp filename', got {line!r}")
        out.append((parse_timestamp_us(parts[0], where=f"{path}: line {line_no}"), parts[1]))
    return out


@dataclass
class TumFolder:
    """An opened TUM folder: description and a frame iterator."""

    root: Path
    description: SensorDescription
    lists: dict[str, list[tuple[int, str]]]

    def count(self, stream: str) -> int:
        return len(self.lists.get(stream, []))

    def frames(self) -> Iterator[Frame]:
        """Depth and colour frames merged in timestamp order; frame number = line index in its list."""
        events = sorted((t, 0 if s == "depth" else 1, i, s, rel)
                        for s, items in self.lists.items() for i, (t, rel) in enumerate(items))
        for t, _, i, stream, rel in events:
            yield Frame(stream=stream, frame_number=i, device_timestamp_us=t, clock_domain="host",
                        host_timestamp_us=t, image=self._read(stream, rel))

    def _read(self, stream: str, rel: str) -> np.ndarray:
        list_file = self.root / ("depth.txt" if stream == "depth" else "rgb.txt")
        # Lexical check (no symlink resolution: TUM folders are often links into a dataset store).
        parts = rel.replace("\\", "/").split("/")
        if not rel or os.path.isabs(rel) or rel.startswith(("/", "\\")) or ".." in parts or "\x00" in rel:
            raise SessionFormatError(f"{list_file}: path {rel!r} escapes the folder {self.root}")
        path = self.root / rel
        data = np.fromfile(path, np.uint8) if path.is_file() else None
        if data is None:
            raise SessionFormatError(f"{path}: missing (listed in {list_file.name})")
        problem = image_structure_problem(data.tobytes())  # before libpng, which prints to stderr
        if problem:
            raise SessionFormatError(f"{path}: {problem}")
        img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        info = self.description.streams[stream]
        if img is None:
            raise SessionFormatError(f"{path}: not a readable image (truncated or corrupt)")
        if img.shape[:2] != (info.height, info.width):
            raise SessionFormatError(f"{path}: image is {img.shape[1]}x{img.shape[0]}, expected {info.width}x{info.height}")
        if stream == "depth":
            if img.dtype != np.uint16 or img.ndim != 2:
                raise SessionFormatError(f"{path}: depth must be a single-channel 16-bit PNG, got {img.dtype} "
                                         f"with {1 if img.ndim == 2 else img.shape[2]} channel(s)")
            return img
        if img.dtype != np.uint8:
            raise SessionFormatError(f"{path}: colour must be 8-bit, got {img.dtype}")
        if img.ndim == 2:
            return cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
        return cv2.cvtColor(img[..., :3], cv2.COLOR_BGR2RGB)


def open_tum(folder: str | os.PathLike, *, intrinsics: Intrinsics | None = None, depth_scale: float = DEPTH_SCALE,
             fps: float = 30.0, with_color: bool = True) -> TumFolder:
    """Open a TUM RGB-D folder (checks the lists and the first image of each; frames are read lazily).

    Args:
        folder: the dataset folder holding ``rgb.txt`` and ``depth.txt``.
        intrinsics: camera model of both streams (default :data:`DEFAULT_INTRINSICS`; its size must
            match the images).
        depth_scale: depth counts per metre (TUM: 5000).
        fps: nominal frame rate (TUM: 30).
        with_color: also read ``rgb.txt``.
    """
    root = Path(folder)
    if not root.is_dir():
        raise SessionFormatError(f"{root}: not a folder" if root.exists() else f"{root}: no such folder")
    if not depth_scale > 0:
        raise SessionFormatError(f"depth scale must be positive, got {depth_scale}")
    lists = {"depth": parse_list(root / "depth.txt")}
    if not lists["depth"]:
        raise SessionFormatError(f"{root / 'depth.txt'}: lists no depth frames (the folder has no depth stream)")
    if with_color:
        lists["color"] = parse_list(root / "rgb.txt")
        if not lists["color"]:
            del lists["color"]
    K = intrinsics or DEFAULT_INTRINSICS
    streams = {"depth": StreamDescription(name="depth", type="depth", width=K.width, height=K.height, fps=float(fps),
                                          encoding="png16", intrinsics=K, depth_unit_m=float(1.0 / depth_scale))}
    if "color" in lists:
        streams["color"] = StreamDescription(name="color", type="color", width=K.width, height=K.height,
                                             fps=float(fps), encoding="png", intrinsics=K)
    desc = SensorDescription(model="Microsoft Kinect v1 (TUM RGB-D)", serial="tum", streams=streams,
                             technology="structured_light",
                             T_depth_color=Transform.identity() if "color" in lists else None,
                             clock={"domain": "host", "note": "TUM timestamps (recording PC clock) in both columns"})
    tum = TumFolder(root, desc, lists)
    for stream, items in lists.items():  # fail early on the first file (size, bit depth)
        tum._read(stream, items[0][1])
    return tum
