"""The session folder: reader, writer and validation.

Layout (documented in ``data_manifests/session.md``)::

    SESSION/
      session.json                 manifest (data_manifests/schemas/session.schema.json)
      <sensor>/frames.csv          append-only index, one row per frame of any of its streams
      <sensor>/<stream>/<n>.png    frames: depth uint16 PNG (0 = none), colour PNG/JPEG
      truth/                       simulated sessions only; alignment never reads it

In memory depth is float32 metres with NaN for "no measurement"; timestamps are int64 µs.
Every error names the file and the problem (:class:`SessionFormatError`).
"""
from __future__ import annotations

import contextlib
import csv
import errno
import io
import json
import os
import shutil
import threading
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd

from capture.camera import Intrinsics, Transform
from capture.errors import CalibrationError, DiskSpaceError, SessionFormatError
from data_manifests import schema_problem
from depthbench import frames as codec
# The frame codec's depth conversions and structure check, importable from here as before.
from depthbench.frames import decode_depth, encode_depth, image_structure_problem  # noqa: F401
from depthbench.fsutil import (atomic_write_json, check_output_free, free_bytes, human_bytes, publish_directory,
                                  read_json, safe_join, sha256_bytes, sha256_file, staging_dir_for)

FORMAT = "depthbench.session"
FORMAT_VERSION = "1.0"
MANIFEST = "session.json"
FRAMES_COLUMNS = ("stream", "frame_number", "device_timestamp_us", "host_timestamp_us", "file", "sha256")
_INT_COLUMNS = ("frame_number", "device_timestamp_us", "host_timestamp_us")


# ----------------------------------------------------------------------------- typed views
@dataclass(frozen=True)
class StreamInfo:
    name: str
    type: str
    width: int
    height: int
    fps: float
    encoding: str
    intrinsics: Intrinsics
    depth_unit_m: float | None = None

    @property
    def period_us(self) -> float:
        """Nominal frame period, µs."""
        return 1e6 / self.fps

    def to_manifest(self) -> dict:
        """The stream's entry of ``session.json`` (``sensors.ID.streams.NAME``)."""
        d = {"type": self.type, "width": int(self.width), "height": int(self.height), "fps": float(self.fps),
             "encoding": self.encoding, "intrinsics": self.intrinsics.to_dict()}
        if self.depth_unit_m is not None:
            d["depth_unit_m"] = float(self.depth_unit_m)
        return d


@dataclass(frozen=True)
class SensorInfo:
    id: str
    role: str
    model: str
    serial: str
    streams: dict[str, StreamInfo]
    frames_path: str
    T_depth_color: Transform | None = None


def _sensor_info(sensor_id: str, d: dict, where: Path) -> SensorInfo:
    streams = {}
    for name, s in d["streams"].items():
        try:
            K = Intrinsics.from_dict(s["intrinsics"])
        except CalibrationError as exc:
            raise SessionFormatError(f"{where}: sensors.{sensor_id}.streams.{name}: {exc}") from None
        if (K.width, K.height) != (s["width"], s["height"]):
            raise SessionFormatError(
                f"{where}: sensors.{sensor_id}.streams.{name}: intrinsics are {K.width}x{K.height} "
                f"but the stream is {s['width']}x{s['height']}")
        streams[name] = StreamInfo(name, s["type"], s["width"], s["height"], float(s["fps"]), s["encoding"], K,
                                   s.get("depth_unit_m"))
    T = None
    if "T_depth_color" in d:
        try:
            T = Transform.from_list(d["T_depth_color"])
        except CalibrationError as exc:
            raise SessionFormatError(f"{where}: sensors.{sensor_id}.T_depth_color: {exc}") from None
    return SensorInfo(sensor_id, d["role"], d["model"], d["serial"], streams, d["frames"], T)


# ----------------------------------------------------------------------------- manifest checks
def validate_manifest(manifest: dict, where: Path) -> None:
    """Check a parsed ``session.json`` against the schema and the rules a schema cannot state."""
    if not isinstance(manifest, dict):
        raise SessionFormatError(f"{where}: top level must be a JSON object")
    if manifest.get("format") != FORMAT:
        raise SessionFormatError(f"{where}: 'format' must be {FORMAT!r}, got {manifest.get('format')!r}")
    version = str(manifest.get("format_version", ""))
    if version.split(".")[0] != FORMAT_VERSION.split(".")[0]:
        raise SessionFormatError(
            f"{where}: unknown format version {version!r} (this reader understands {FORMAT_VERSION.split('.')[0]}.x)")
    problem = schema_problem("session", manifest)
    if problem:
        raise SessionFormatError(f"{where}: {problem}")
    for e in manifest.get("extrinsics", []):
        for end in ("dst", "src"):
            if e[end] not in manifest["sensors"]:
                raise SessionFormatError(f"{where}: extrinsics names unknown sensor {e[end]!r}")
        try:
            Transform.from_list(e["T"])
        except CalibrationError as exc:
            raise SessionFormatError(f"{where}: extrinsics {e['dst']}<-{e['src']}: {exc}") from None


def _read_frames_csv(path: Path, sensor: SensorInfo, *, sha256: str | None = None) -> pd.DataFrame:
    """Parse and check a sensor's ``frames.csv`` (against ``sha256`` from ``session.json`` if given)."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise SessionFormatError(f"{path}: frames table is missing") from None
    except OSError as exc:
        raise SessionFormatError(f"{path}: frames table cannot be read ({exc.strerror})") from None
    if sha256 is not None and sha256_bytes(data) != sha256:
        raise SessionFormatError(f"{path}: checksum mismatch with session.json")
    try:
        text = data.decode()
    except UnicodeDecodeError:
        raise SessionFormatError(f"{path}: not a text table (not UTF-8)") from None
    rows = list(csv.reader(io.StringIO(text)))
    if not rows or tuple(rows[0]) != FRAMES_COLUMNS:
        raise SessionFormatError(f"{path}: header must be {','.join(FRAMES_COLUMNS)}")
    body = rows[1:]
    for line, row in enumerate(body, start=2):
        if len(row) != len(FRAMES_COLUMNS):
            raise SessionFormatError(f"{path}: line {line}: expected {len(FRAMES_COLUMNS)} fields, got {len(row)}")
    df = pd.DataFrame(body, columns=list(FRAMES_COLUMNS))
    for col in _INT_COLUMNS:
        try:
            df[col] = df[col].astype(np.int64)
        except (ValueError, OverflowError):
            bad = next(i for i, v in enumerate(df[col]) if not _is_int(v))
            raise SessionFormatError(f"{path}: line {bad + 2}: {col} {df[col][bad]!r} is not an integer") from None
    bad_sha = np.flatnonzero(~df["sha256"].str.fullmatch(r"[0-9a-f]{64}").to_numpy(bool))
    if bad_sha.size:
        raise SessionFormatError(f"{path}: line {bad_sha[0] + 2}: sha256 {df['sha256'][bad_sha[0]]!r} is not 64 lowercase hex digits")
    unknown = sorted(set(df["stream"]) - set(sensor.streams))
    if unknown:
        raise SessionFormatError(f"{path}: rows name stream {unknown[0]!r}, which session.json does not declare")
    for stream, g in df.groupby("stream", sort=False):
        idx = g.index.to_numpy()
        for col in _INT_COLUMNS:
            steps = np.diff(g[col].to_numpy())
            bad = np.flatnonzero(steps <= 0) if col == "frame_number" else np.flatnonzero(steps < 0)
            if bad.size:
                what = "frame numbers do not increase" if col == "frame_number" else f"{col} goes backwards"
                raise SessionFormatError(f"{path}: line {idx[bad[0] + 1] + 2}: stream {stream}: {what}")
    return df


def _is_int(v: str) -> bool:
    try:
        int(v)
        return True
    except ValueError:
        return False


# ----------------------------------------------------------------------------- the reader
class Session:
    """A session folder opened for reading; checks the manifest and every frames table on open.

    ``verify="full"`` also decodes every frame and checks checksum, dtype and size.
    """

    def __init__(self, root: str | os.PathLike, *, verify: str = "index") -> None:
        self.root = Path(root)
        self.manifest_path = self.root / MANIFEST
        if not self.root.is_dir():
            raise SessionFormatError(f"{self.root}: not a session folder (does not exist or is not a folder)")
        self.manifest = read_json(self.manifest_path, error=SessionFormatError, missing=" (not a session folder)")
        validate_manifest(self.manifest, self.manifest_path)
        self.sensors = {sid: _sensor_info(sid, d, self.manifest_path) for sid, d in self.manifest["sensors"].items()}
        self._frames: dict[str, pd.DataFrame] = {}
        for sid, sensor in self.sensors.items():
            path = self._safe(sensor.frames_path, self.manifest_path)
            df = _read_frames_csv(path, sensor, sha256=self.manifest.get("checksums", {}).get(sensor.frames_path))
            for f in df["file"]:
                self._safe(f, path)
            self._frames[sid] = df
        if verify == "full":
            self.verify_frames()

    # -- manifest views
    @property
    def name(self) -> str:
        return self.manifest["name"]

    @property
    def time_base(self) -> str:
        return self.manifest["time_base"]

    @property
    def effects(self) -> dict:
        return dict(self.manifest.get("effects", {}))

    @property
    def clock_facts(self) -> dict:
        return dict(self.manifest.get("clock_facts", {}))

    def sensors_with_role(self, role: str) -> list[str]:
        return [sid for sid, s in self.sensors.items() if s.role == role]

    def declared_extrinsics(self, dst: str, src: str) -> Transform | None:
        for e in self.manifest.get("extrinsics", []):
            if (e["dst"], e["src"]) == (dst, src):
                return Transform.from_list(e["T"])
            if (e["dst"], e["src"]) == (src, dst):
                return Transform.from_list(e["T"]).inverse()
        return None

    def stream(self, sensor: str, stream: str) -> StreamInfo:
        try:
            return self.sensors[sensor].streams[stream]
        except KeyError:
            raise SessionFormatError(f"{self.manifest_path}: no stream {sensor}/{stream}") from None

    def intrinsics(self, sensor: str, stream: str = "depth") -> Intrinsics:
        return self.stream(sensor, stream).intrinsics

    # -- frames
    def frames(self, sensor: str, stream: str | None = None) -> pd.DataFrame:
        """The frames table of ``sensor`` (one stream's rows if given), in recorded order."""
        df = self._frames[sensor]
        if stream is not None:
            self.stream(sensor, stream)
            df = df[df["stream"] == stream].reset_index(drop=True)
        return df

    def timestamps_us(self, sensor: str, stream: str = "depth") -> np.ndarray:
        """int64 µs timestamps of a stream on the session's ``time_base``."""
        return self.frames(sensor, stream)[f"{self.time_base}_timestamp_us"].to_numpy(np.int64)

    def _safe(self, rel: str, source: Path) -> Path:
        return safe_join(self.root, rel, source=source, error=SessionFormatError)

    def _row(self, sensor: str, stream: str, frame_number: int):
        df = self.frames(sensor, stream)
        hit = np.flatnonzero(df["frame_number"].to_numpy() == frame_number)
        if hit.size == 0:
            raise SessionFormatError(f"{self.root / self.sensors[sensor].frames_path}: no frame {frame_number} in stream {stream}")
        return df.iloc[hit[0]]

    def frame_path(self, sensor: str, stream: str, frame_number: int) -> Path:
        """The file of one frame (inside the session folder; not checked for presence)."""
        row = self._row(sensor, stream, frame_number)
        return self._safe(row["file"], self.root / self.sensors[sensor].frames_path)

    def read_image(self, sensor: str, stream: str, frame_number: int, *, verify: bool = True) -> np.ndarray:
        """The stored image as it is on disk (uint16 counts for depth, RGB uint8 for colour)."""
        info = self.stream(sensor, stream)
        row = self._row(sensor, stream, frame_number)
        table = self.sensors[sensor].frames_path
        path = self._safe(row["file"], self.root / table)
        data = codec.read_frame_bytes(path, sha256=row["sha256"] if verify else None, table=table,
                                      error=SessionFormatError)
        img = codec.decode_image(data, where=path, error=SessionFormatError)
        if img.shape[:2] != (info.height, info.width):
            raise SessionFormatError(f"{path}: frame is {img.shape[1]}x{img.shape[0]}, stream is {info.width}x{info.height}")
        if info.encoding == "png16":
            return codec.check_depth_counts(img, where=path, error=SessionFormatError)
        return codec.to_rgb(img, where=path, error=SessionFormatError)

    def read_depth(self, sensor: str, frame_number: int, *, stream: str = "depth", verify: bool = True) -> np.ndarray:
        """Depth as float32 metres ``(H, W)`` with NaN where there is no measurement."""
        info = self.stream(sensor, stream)
        return decode_depth(self.read_image(sensor, stream, frame_number, verify=verify), info.depth_unit_m)

    def read_color(self, sensor: str, frame_number: int, *, stream: str = "color", verify: bool = True) -> np.ndarray:
        """Colour as RGB uint8 ``(H, W, 3)``."""
        return self.read_image(sensor, stream, frame_number, verify=verify)

    def verify_frames(self) -> int:
        """Decode every frame and check checksum, dtype and size; returns the number checked."""
        n = 0
        for sid, df in self._frames.items():
            for stream, fn in zip(df["stream"], df["frame_number"]):
                self.read_image(sid, stream, int(fn))
                n += 1
        return n

    def check_frame_files(self, sensors=None) -> int:
        """Check that every indexed frame file of ``sensors`` (default all) is present, a regular
        file and readable, without reading it (one ``stat`` each; for a long job to fail at once
        rather than at the frame). Returns the number checked; raises :class:`SessionFormatError`."""
        n = 0
        for sid in self.sensors if sensors is None else sensors:
            table = self.sensors[sid].frames_path
            paths = (self._safe(rel, self.root / table) for rel in self._frames[sid]["file"])
            n += codec.check_frame_files(paths, table=table, error=SessionFormatError)
        return n


def open_session(path: str | os.PathLike, *, verify: str = "index") -> Session:
    return Session(path, verify=verify)


# ----------------------------------------------------------------------------- frame files
def encode_frame(image: np.ndarray, info: StreamInfo, *, fast: bool = False, where: str = "frame") -> tuple[bytes, str]:
    """One frame of the stream ``info`` as the session stores it: ``(file bytes, extension)``.

    Depth/IR (``png16``): uint16 counts or float metres (NaN = none) ``(H, W)``; colour: RGB uint8
    ``(H, W, 3)``, PNG or JPEG as the stream's ``encoding`` says. PNG settings
    :data:`depthbench.frames.PNG_RLE`, or with ``fast`` :data:`~depthbench.frames.PNG_STORED` (same
    pixels, larger file, several times less CPU). ``where`` names the frame in errors."""
    params = codec.PNG_STORED if fast else codec.PNG_RLE
    img = np.asarray(image)
    if img.shape[:2] != (info.height, info.width):
        raise SessionFormatError(f"{where}: frame is {img.shape[1]}x{img.shape[0]}, stream is {info.width}x{info.height}")
    if info.encoding == "png16":
        unit = info.depth_unit_m if info.type == "depth" else 1.0
        return codec.encode_depth_png(img, unit_m=unit, params=params, where=where, error=SessionFormatError), "png"
    return codec.encode_color(img, encoding=info.encoding, params=params, where=where, error=SessionFormatError)


# ----------------------------------------------------------------------------- disk space
#: Bytes of one ``frames.csv`` row, at most (stream name, three integers, path, sha256).
_ROW_BYTES = 200


def frame_bytes_bound(info: StreamInfo) -> int:
    """Most bytes one frame of the stream ``info`` takes on disk, index row included: its largest
    encoding (:func:`depthbench.frames.encoded_size_bound`: the uncompressed PNG the recorder writes
    while falling behind)."""
    depth_like = info.encoding == "png16"
    return _ROW_BYTES + codec.encoded_size_bound(info.width, info.height, channels=1 if depth_like else 3,
                                                 bytes_per_sample=2 if depth_like else 1)


def check_disk_space(out: str | os.PathLike, streams, seconds: float) -> int:
    """Refuse (:class:`DiskSpaceError`) to write ``seconds`` of ``streams`` (:class:`StreamInfo`, each at
    its nominal ``fps``) into the session folder ``out`` when even the free space of its file system
    is smaller than the most they can take (:func:`frame_bytes_bound`). Returns that bound."""
    streams = list(streams)
    per_s = sum(st.fps * frame_bytes_bound(st) for st in streams)
    need = per_s * float(seconds)
    free = free_bytes(out)
    if need > free:
        raise DiskSpaceError(f"{out}: {seconds:g} s of {len(streams)} streams can take up to {human_bytes(need)} "
                             f"({human_bytes(per_s)}/s as uncompressed frames), and its disk has {human_bytes(free)} "
                             "free")
    return int(need)


# ----------------------------------------------------------------------------- the writer
class SessionWriter:
    """Writes a session: frames first (temporary name, then rename), then their index row.

    ``staged=True`` builds the folder under a temporary sibling name and publishes it on
    :meth:`close` (for the simulator and importers: no partial output on error).
    ``staged=False`` writes in place (the recorder: a crash leaves a readable session up to the
    last complete frame; ``depthbench capture repair`` tidies the rest).
    """

    def __init__(self, root: str | os.PathLike, manifest: dict, *, force: bool = False, staged: bool = True,
                 fsync: bool = False) -> None:
        self.final_root = Path(root)
        check_output_free(self.final_root, force=force, what="session folder")
        self.force, self.staged, self.fsync = force, staged, fsync
        self.manifest = self._complete_manifest(manifest)
        validate_manifest(self.manifest, self.final_root / MANIFEST)
        self.sensors = {sid: _sensor_info(sid, d, self.final_root / MANIFEST)
                        for sid, d in self.manifest["sensors"].items()}
        self._index: dict[str, int] = {}  # sensor -> O_APPEND file descriptor of its frames.csv
        self._last: dict[tuple[str, str], tuple[int, int, int]] = {}
        self._lock = threading.Lock()
        self.final_root.parent.mkdir(parents=True, exist_ok=True)
        # The skeleton (folders, frames.csv headers, session.json) is built under a temporary
        # sibling name, so the folder appears complete or not at all. ``staged`` keeps it there
        # until close(); otherwise it is published at once and frames are written in place.
        self.root = staging_dir_for(self.final_root)
        try:
            for sid, s in self.sensors.items():
                for stream in s.streams:
                    (self.root / sid / stream).mkdir(parents=True, exist_ok=True)
                index_path = self._safe_output(s.frames_path)
                index_path.parent.mkdir(parents=True, exist_ok=True)
                fd = os.open(index_path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
                self._index[sid] = fd
                if os.fstat(fd).st_size == 0:
                    os.write(fd, (",".join(FRAMES_COLUMNS) + "\n").encode())
            atomic_write_json(self.root / MANIFEST, self.manifest, fsync=fsync)
            if not staged:
                if self.final_root.exists():  # only reached with force, or when it is an empty folder
                    shutil.rmtree(self.final_root)
                os.replace(self.root, self.final_root)
                self.root = self.final_root
        except BaseException:
            self._close_index()
            shutil.rmtree(self.root, ignore_errors=True)
            raise
        self.closed = False

    @staticmethod
    def _complete_manifest(manifest: dict) -> dict:
        m = json.loads(json.dumps(manifest))  # deep copy, JSON-only
        m.setdefault("format", FORMAT)
        m.setdefault("format_version", FORMAT_VERSION)
        m.setdefault("created_utc", datetime.now(timezone.utc).isoformat(timespec="seconds"))
        m.setdefault("time_base", "host")
        m["status"] = "recording"
        for sid, s in m.get("sensors", {}).items():
            s.setdefault("frames", f"{sid}/frames.csv")
        return m

    def add_frame(self, sensor: str, stream: str, frame_number: int, device_timestamp_us: int,
                  host_timestamp_us: int, image: np.ndarray) -> str:
        """Write one frame and index it. Depth: uint16 counts or float metres (NaN = none).
        Colour: RGB uint8. Returns the frame's path relative to the session folder."""
        self._check_order(sensor, stream, frame_number, device_timestamp_us, host_timestamp_us)
        rel, sha = self.write_frame_file(sensor, stream, frame_number, image)
        self.index_frame(sensor, stream, frame_number, device_timestamp_us, host_timestamp_us, rel, sha)
        return rel

    def _check_order(self, sensor: str, stream: str, frame_number: int, dev: int, host: int) -> None:
        last = self._last.get((sensor, stream))
        if last is not None:
            lf, ld, lh = last
            if int(frame_number) <= lf or int(dev) < ld or int(host) < lh:
                raise SessionFormatError(f"{sensor}/{stream}: frame {frame_number} does not follow frame {lf} in order")

    def write_frame_file(self, sensor: str, stream: str, frame_number: int, image: np.ndarray, *,
                         fast: bool = False) -> tuple[str, str]:
        """Encode and write one frame file (temporary name, then rename), without indexing it.

        Thread-safe (encoders release the GIL). ``fast``: PNG without compression (same pixels,
        larger file). Returns ``(path relative to the session, sha256)``; call :meth:`index_frame`
        with them, in frame order per stream."""
        info = self.sensors[sensor].streams[stream]
        data, ext = encode_frame(image, info, fast=fast, where=f"{sensor}/{stream}")
        rel = f"{sensor}/{stream}/{int(frame_number):08d}.{ext}"
        return rel, codec.write_frame_file(self.root / rel, data, fsync=self.fsync)

    def index_frame(self, sensor: str, stream: str, frame_number: int, device_timestamp_us: int,
                    host_timestamp_us: int, rel: str, sha256: str) -> None:
        """Append one row to the sensor's ``frames.csv`` with a single ``write`` (a killed process
        leaves whole rows). The frame file must already be in place."""
        frame_number, dev, host = int(frame_number), int(device_timestamp_us), int(host_timestamp_us)
        with self._lock:
            self._check_order(sensor, stream, frame_number, dev, host)
            fd = self._index[sensor]
            row = f"{stream},{frame_number},{dev},{host},{rel},{sha256}\n".encode()
            start = os.lseek(fd, 0, os.SEEK_END)
            try:
                written = os.write(fd, row)
                if written != len(row):
                    raise OSError(errno.ENOSPC, "short write to the frames table")
            except OSError:
                os.ftruncate(fd, start)  # never leave half a row behind
                raise
            if self.fsync:
                os.fsync(fd)
            self._last[(sensor, stream)] = (frame_number, dev, host)

    def _safe_output(self, rel: str) -> Path:
        return safe_join(self.root, rel, source=self.root / MANIFEST, error=SessionFormatError)

    def _close_index(self) -> None:
        for fd in self._index.values():
            with contextlib.suppress(OSError):
                os.close(fd)
        self._index = {}

    def update_manifest(self, **fields) -> None:
        """Set top-level manifest fields (e.g. per-stream drop counts) before :meth:`close`."""
        self.manifest.update(json.loads(json.dumps(fields)))
        validate_manifest(self.manifest, self.root / MANIFEST)

    def set_stream_counts(self, sensor: str, stream: str, **counts: int) -> None:
        """Set per-stream counters (``dropped_frames``, ``duplicate_frames``...) in the manifest."""
        self.manifest["sensors"][sensor]["streams"][stream].update({k: int(v) for k, v in counts.items()})

    def write_manifest(self) -> None:
        """Write the manifest as it is now (atomically), e.g. periodically while recording."""
        atomic_write_json(self.root / MANIFEST, self.manifest, fsync=self.fsync)

    def close(self, status: str = "complete") -> Path:
        """Finish: checksums of the frames tables, status, and (staged) publish the folder."""
        if self.closed:
            return self.final_root
        self._close_index()
        self.manifest["checksums"] = {s.frames_path: sha256_file(self.root / s.frames_path) for s in self.sensors.values()}
        self.manifest["status"] = status
        atomic_write_json(self.root / MANIFEST, self.manifest, fsync=self.fsync)
        if self.staged:
            self.root = publish_directory(self.root, self.final_root)
        self.closed = True
        return self.final_root

    def abort(self) -> None:
        """Stop writing; a staged folder is removed, an in-place one is left as recorded so far."""
        self._close_index()
        if self.staged:
            shutil.rmtree(self.root, ignore_errors=True)
        self.closed = True

    def __enter__(self) -> "SessionWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
