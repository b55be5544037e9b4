"""The frame codec: every frame file any stage writes or reads goes through this module.

On disk (the formats of ``data_manifests/session.md``, ``truth.md``, ``aligned.md``, ``denoised.md``):

* **depth**: single-channel ``uint16`` PNG of counts of a stated unit (``unit_m`` metres per count,
  e.g. a session stream's ``depth_unit_m``, 1e-4 for truth and aligned datasets); ``0`` = no
  measurement. Depths outside ``[unit_m, 65535 unit_m]`` (after rounding) are written as 0.
* **colour**: 8-bit, 3-channel PNG or JPEG (quality :data:`JPEG_QUALITY`), stored in the BGR
  channel order OpenCV and every PNG/JPEG reader agree on (it is the file's RGB).
* **mask**: single-channel ``uint8`` PNG, 0 or 255.
* every frame file is identified by the sha256 of its bytes, recorded in the index table beside it
  (``frames.csv``); readers compare before decoding.

In memory: depth ``(H, W)`` float32 metres with NaN holes; colour ``(H, W, 3)`` RGB uint8; masks bool.

The PNG settings are part of each format (they decide the bytes, hence the checksums and an
aligned dataset's identity), so they are named here and each writer states which it uses:
:data:`PNG_RLE` (recorded and imported sessions), :data:`PNG_FAST` (simulated sessions and their
truth), :data:`PNG_STORED` (the recorder falling behind) and :data:`PNG_LEVEL1` (aligned datasets,
denoised outputs). Any PNG decoder reads all four.

Errors: every function that can meet a bad file or a bad image takes ``error``, the exception type
to raise (the caller's package error, e.g. ``SessionFormatError``); the message is one line that
starts with the file (``where``) and names the problem.
"""
from __future__ import annotations

import os
import stat
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from isal import isal_zlib

from depthbench.errors import FrameError
from depthbench.fsutil import atomic_write_bytes, sha256_bytes

#: zlib level 1, run-length strategy, "up" filter: about 3x faster than OpenCV's default at the
#: same size on depth images. Recorded and imported sessions.
PNG_RLE = (cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE,
           cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_UP)
#: Stored (uncompressed) deflate blocks, no filter: about 8x faster than :data:`PNG_RLE` and
#: 1.5-3x larger; the recorder uses it while it is falling behind.
PNG_STORED = (cv2.IMWRITE_PNG_COMPRESSION, 0, cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE)
#: zlib level 1 with OpenCV's default strategy and filter: aligned datasets and denoised outputs.
PNG_LEVEL1 = (cv2.IMWRITE_PNG_COMPRESSION, 1)


@dataclass(frozen=True)
class FastPng:
    """PNG settings written by this module rather than OpenCV: the "up" filter on every row and
    ISA-L's deflate (the ``isal`` package; assembly, several times faster than zlib) at ``level``
    (0-3). 8-bit or 16-bit, 1 or 3 channels, no interlacing; any PNG decoder reads it."""

    level: int = 1


#: "Up" filter and ISA-L deflate level 1: the pixels of :data:`PNG_RLE` at about its size, with 5-8x
#: less CPU (the simulator's 640x480 frames: depth 2.8 against 19 ms, colour 10 against 60 ms,
#: ``perf/simulate_fps.py``). Simulated sessions and their truth. The bytes are those of the ISA-L
#: version installed (as :data:`PNG_RLE`'s are OpenCV's zlib's); the pixels never change.
PNG_FAST = FastPng(level=1)
#: JPEG quality of colour streams stored as JPEG.
JPEG_QUALITY = 95
#: File name extension of each colour encoding (a session stream's ``encoding``).
COLOR_EXTENSIONS = {"png": "png", "jpeg": "jpg"}

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


# ----------------------------------------------------------------------------- depth <-> counts
def encode_depth(depth_m: np.ndarray, depth_unit_m: float) -> np.ndarray:
    """Depth ``(H, W)`` in metres (NaN = none) to uint16 counts of ``depth_unit_m`` metres
    (0 = none); values that round outside 1..65535 counts become 0."""
    counts = np.rint(np.asarray(depth_m, dtype=np.float64) / depth_unit_m)
    bad = ~np.isfinite(counts) | (counts < 1) | (counts > 65535)
    counts[bad] = 0
    return counts.astype(np.uint16)


def decode_depth(counts: np.ndarray, depth_unit_m: float) -> np.ndarray:
    """uint16 counts ``(H, W)`` (0 = none) to float32 metres with NaN holes."""
    depth = counts.astype(np.float32) * np.float32(depth_unit_m)
    depth[counts == 0] = np.nan
    return depth


# ----------------------------------------------------------------------------- encoding
def encode_png(img: np.ndarray, *, params=PNG_RLE, where: str = "image",
               error: type[Exception] = FrameError) -> bytes:
    """PNG bytes of ``img`` as given (uint8/uint16, 1 or 3 channels in OpenCV's channel order: BGR
    for the file's RGB); ``params``: OpenCV's settings or a :class:`FastPng`."""
    if isinstance(params, FastPng):
        return _fast_png(img, level=params.level, bgr=True, where=where, error=error)
    ok, buf = cv2.imencode(".png", img, params)
    if not ok:  # pragma: no cover - OpenCV encodes every uint8/uint16 image
        raise error(f"{where}: could not encode as PNG")
    return buf.tobytes()


def encode_depth_png(depth: np.ndarray, *, unit_m: float, params=PNG_RLE, where: str = "depth",
                     error: type[Exception] = FrameError) -> bytes:
    """A depth PNG: ``depth`` is float metres (NaN = none; converted with :func:`encode_depth`)
    or uint16 counts already in ``unit_m``, shape ``(H, W)``."""
    img = np.asarray(depth)
    if img.dtype.kind == "f":
        img = encode_depth(img, unit_m)
    if img.dtype != np.uint16 or img.ndim != 2:
        raise error(f"{where}: 16-bit frames must be (H, W) uint16 or float metres, got {img.dtype} {img.shape}")
    return encode_png(img, params=params, where=where, error=error)


def encode_color(rgb: np.ndarray, *, encoding: str = "png", params=PNG_RLE, where: str = "colour",
                 error: type[Exception] = FrameError) -> tuple[bytes, str]:
    """RGB uint8 ``(H, W, 3)`` as ``encoding`` (``"png"`` or ``"jpeg"``); returns ``(bytes, extension)``."""
    img = np.asarray(rgb)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise error(f"{where}: colour must be (H, W, 3) RGB uint8, got {img.dtype} {img.shape}")
    if encoding not in COLOR_EXTENSIONS:
        raise error(f"{where}: colour encoding must be one of {', '.join(COLOR_EXTENSIONS)}, got {encoding!r}")
    if encoding == "png" and isinstance(params, FastPng):
        return _fast_png(img, level=params.level, bgr=False, where=where, error=error), "png"
    bgr = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    if encoding == "jpeg":
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        if not ok:  # pragma: no cover
            raise error(f"{where}: could not encode as JPEG")
        return buf.tobytes(), "jpg"
    return encode_png(bgr, params=params, where=where, error=error), "png"


def _fast_png(img: np.ndarray, *, level: int, bgr: bool, where: str, error: type[Exception]) -> bytes:
    """:class:`FastPng` bytes of ``img`` ``(H, W)`` or ``(H, W, 3)`` uint8/uint16; ``bgr``: the
    channels are in OpenCV's order (reversed into the file's RGB), else already RGB."""
    img = np.asarray(img)
    channels = 1 if img.ndim == 2 else (img.shape[2] if img.ndim == 3 else 0)
    if img.dtype not in (np.uint8, np.uint16) or channels not in (1, 3):
        raise error(f"{where}: could not encode {img.dtype} {img.shape} as PNG (uint8/uint16, 1 or 3 channels)")
    if channels == 3 and bgr:
        img = img[..., ::-1]
    h, w = img.shape[:2]
    # PNG samples are big-endian; the rows as bytes, each after its filter-type byte (2 = "up":
    # the byte minus the byte above it, modulo 256; the row above the first is zeros)
    raw = np.ascontiguousarray(img, dtype=">u2" if img.dtype == np.uint16 else np.uint8).view(np.uint8).reshape(h, -1)
    rows = np.empty((h, raw.shape[1] + 1), np.uint8)
    rows[:, 0] = 2
    rows[0, 1:] = raw[0]
    np.subtract(raw[1:], raw[:-1], out=rows[1:, 1:])
    header = struct.pack(">IIBBBBB", w, h, 8 * img.dtype.itemsize, 0 if channels == 1 else 2, 0, 0, 0)
    return b"".join((_PNG_SIGNATURE, _chunk(b"IHDR", header), _chunk(b"IDAT", isal_zlib.compress(rows, level)),
                     _chunk(b"IEND", b"")))


def _chunk(kind: bytes, data: bytes) -> bytes:
    """A PNG chunk: length, type, data, CRC-32 of type and data."""
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", isal_zlib.crc32(data, isal_zlib.crc32(kind)))


def encode_mask_png(mask: np.ndarray, *, params=PNG_RLE, where: str = "mask",
                    error: type[Exception] = FrameError) -> bytes:
    """A mask ``(H, W)`` (true where set) as a uint8 PNG of 0/255."""
    return encode_png(np.where(np.asarray(mask), 255, 0).astype(np.uint8), params=params, where=where, error=error)


def encoded_size_bound(width: int, height: int, *, channels: int, bytes_per_sample: int = 1) -> int:
    """Upper bound of the bytes of a frame of this shape as this codec writes it: the
    :data:`PNG_STORED` PNG (raw rows with their filter byte, 5 bytes per stored deflate block of at
    most 65535 bytes, 1 KiB for signature and chunks); the other PNG settings and JPEG at
    :data:`JPEG_QUALITY` write fewer bytes."""
    raw = (width * channels * bytes_per_sample + 1) * height
    return raw + 5 * (raw // 65535 + 1) + 1024


# ----------------------------------------------------------------------------- decoding
def image_structure_problem(data: bytes) -> str | None:
    """Why ``data`` is not a complete PNG or JPEG file, or ``None``.

    PNG: the signature, every chunk's length and CRC, and a final IEND chunk (catches truncation
    and flipped bytes without handing broken data to libpng, which prints to stderr).
    JPEG: the SOI and EOI markers."""
    if data.startswith(_PNG_SIGNATURE):
        pos, n = len(_PNG_SIGNATURE), len(data)
        while pos + 12 <= n:
            length = int.from_bytes(data[pos:pos + 4], "big")
            end = pos + 12 + length
            if end > n:
                return "truncated PNG (a chunk runs past the end of the file)"
            if zlib.crc32(data[pos + 4:end - 4]) != int.from_bytes(data[end - 4:end], "big"):
                return f"corrupt PNG (CRC error in chunk {data[pos + 4:pos + 8].decode('latin-1')!r})"
            if data[pos + 4:pos + 8] == b"IEND":
                return None
            pos = end
        return "truncated PNG (no IEND chunk)"
    if data.startswith(b"\xff\xd8"):
        return None if data.rstrip(b"\x00").endswith(b"\xff\xd9") else "truncated JPEG (no end-of-image marker)"
    return "not a PNG or JPEG file" if data else "empty file"


def decode_image(data: bytes, *, where, error: type[Exception] = FrameError, shape: tuple[int, int] | None = None
                 ) -> np.ndarray:
    """Decode PNG/JPEG bytes as stored (uint16 or uint8, channels in the file's BGR order).

    Checks the file's structure first (:func:`image_structure_problem`) and, if given, its
    ``shape`` ``(H, W)``."""
    problem = image_structure_problem(data)
    if problem:
        raise error(f"{where}: {problem}")
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise error(f"{where}: not a readable image (truncated or corrupt)")
    if shape is not None and img.shape[:2] != tuple(shape):
        raise error(f"{where}: image is {img.shape[1]}x{img.shape[0]}, expected {shape[1]}x{shape[0]}")
    return img


def check_depth_counts(img: np.ndarray, *, where, error: type[Exception] = FrameError) -> np.ndarray:
    """``img`` if it is a single-channel uint16 image (depth counts); otherwise one-line error."""
    if img.dtype != np.uint16 or img.ndim != 2:
        channels = 1 if img.ndim == 2 else img.shape[2]
        raise error(f"{where}: depth must be single-channel 16-bit, got {8 * img.dtype.itemsize}-bit with "
                    f"{channels} channel(s)")
    return img


def decode_depth_png(data: bytes, *, unit_m: float, where, error: type[Exception] = FrameError,
                     shape: tuple[int, int] | None = None) -> np.ndarray:
    """A depth PNG to ``(H, W)`` float32 metres with NaN holes (counts times ``unit_m``)."""
    img = check_depth_counts(decode_image(data, where=where, error=error, shape=shape), where=where, error=error)
    return decode_depth(img, unit_m)


def to_rgb(img: np.ndarray, *, where, error: type[Exception] = FrameError) -> np.ndarray:
    """A decoded 8-bit colour image (grey, BGR or BGRA as stored) as RGB ``(H, W, 3)`` uint8."""
    if img.dtype != np.uint8:
        raise error(f"{where}: colour must be 8-bit, got {img.dtype}")
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    return cv2.cvtColor(np.ascontiguousarray(img[..., :3]), cv2.COLOR_BGR2RGB)


def decode_color(data: bytes, *, where, error: type[Exception] = FrameError,
                 shape: tuple[int, int] | None = None) -> np.ndarray:
    """PNG/JPEG colour bytes to RGB ``(H, W, 3)`` uint8."""
    return to_rgb(decode_image(data, where=where, error=error, shape=shape), where=where, error=error)


# ----------------------------------------------------------------------------- files
def file_problem(path: str | os.PathLike) -> str | None:
    """Why the frame file ``path`` cannot be read, or ``None``: missing, not a regular file
    (a folder, a FIFO, a device), or no read permission. Reads nothing (one ``stat``)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return "missing"
    except OSError as exc:
        return f"cannot be read ({exc.strerror})"
    if not stat.S_ISREG(st.st_mode):
        return "not a regular file"
    if not os.access(path, os.R_OK):
        return "cannot be read (Permission denied)"
    return None


def _problem_text(what: str, problem: str) -> str:
    """``"frame file is missing"``, ``"frame file cannot be read (...)"``."""
    return f"{what} {problem}" if problem.startswith("cannot") else f"{what} is {problem}"


def check_frame_files(paths, *, table, error: type[Exception] = FrameError) -> int:
    """Check that every frame file of ``paths`` (listed in the index ``table``) is present, a regular
    file and readable, without reading any (:func:`file_problem`): for a long job to fail at once
    rather than at the frame. Returns the number checked."""
    n = 0
    for path in paths:
        problem = file_problem(path)
        if problem:
            raise error(f"{path}: {_problem_text(f'frame file listed in {table}', problem)}")
        n += 1
    return n


def read_frame_bytes(path: str | os.PathLike, *, sha256: str | None, table, what: str = "frame file",
                     error: type[Exception] = FrameError) -> bytes:
    """The bytes of the frame file ``path``, checked against ``sha256`` (from the index ``table``,
    named in the message; ``None`` skips the check). One-line errors for a file that is missing,
    not a regular file, unreadable, or does not match its checksum."""
    problem = file_problem(path)
    if problem:
        raise error(f"{path}: {_problem_text(what, problem)}")
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as exc:
        raise error(f"{path}: {what} cannot be read ({exc.strerror})") from None
    if sha256 is not None and sha256_bytes(data) != sha256:
        raise error(f"{path}: checksum mismatch with {table}")
    return data


def write_frame_file(path: str | os.PathLike, data: bytes, *, fsync: bool = False) -> str:
    """Write an encoded frame through a temporary name and a rename; returns its sha256."""
    atomic_write_bytes(Path(path), data, fsync=fsync)
    return sha256_bytes(data)
