"""Import recordings into session folders: RealSense ``.db3``, Azure Kinect ``.mkv``, TUM RGB-D folders.

One function per format (:func:`import_realsense`, :func:`import_azure_kinect`, :func:`import_tum`),
each returning an :class:`ImportResult`. They read through the format's reader in
``capture/drivers/`` (which yields :class:`~capture.drivers.base.Frame` objects) and write with
:class:`~capture.session.SessionWriter` in staged mode: the session appears only when complete, an
error leaves nothing behind, and an existing output is replaced only with ``force=True``.

What an import writes besides the frames:

* ``session.json``: the device facts (model, serial, firmware, technology, intrinsics, depth unit,
  ``T_depth_color``, clock facts) and ``source`` (importer, input files with their size and sha256,
  how host timestamps were obtained, conversion notes);
* per stream ``dropped_frames`` (gaps in the frame numbers) and ``duplicate_frames`` (a frame number
  seen again; the repeat is not written);
* ``SENSOR/frame_metadata.csv`` when the source has per-frame metadata (RealSense): ``stream,
  frame_number, clock_domain`` and one column per metadata field (empty = not reported).

Frames whose device timestamp goes backwards, or whose frame number goes back (a counter reset),
are skipped and counted (``source.skipped_out_of_order``), since a session's timestamps never
decrease. Host timestamps are made non-decreasing per stream (a stepped system clock).
"""
from __future__ import annotations

import csv
import io
from collections import deque
from concurrent.futures import ThreadPoolExecutor
import logging
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

from capture.camera import Intrinsics
from capture.drivers.base import Frame, SensorDescription
from capture.errors import CaptureError, SessionFormatError
from capture.session import SessionWriter
from depthbench.fsutil import atomic_write_text, check_output_free, sha256_file

log = logging.getLogger(__name__)

ROLES = ("lq", "hq", "view")
_ID = re.compile(r"^[a-z0-9_]{1,32}$")


@dataclass
class StreamReport:
    """What was imported for one stream."""

    frames: int = 0
    dropped: int = 0
    duplicates: int = 0
    out_of_order: int = 0
    first_device_us: int | None = None
    last_device_us: int | None = None


@dataclass(frozen=True)
class ImportResult:
    """An imported session: where it is and, per sensor and stream, what went in."""

    session: Path
    importer: str
    streams: dict[str, dict[str, StreamReport]]
    notes: dict[str, Any] = field(default_factory=dict)

    @property
    def total_frames(self) -> int:
        return sum(r.frames for s in self.streams.values() for r in s.values())

    def summary(self) -> str:
        """Human-readable lines: one per stream."""
        lines = [f"{self.session}: imported {self.total_frames} frames ({self.importer})"]
        for sid, streams in self.streams.items():
            for name, r in streams.items():
                span = ((r.last_device_us - r.first_device_us) / 1e6
                        if r.first_device_us is not None and r.last_device_us is not None else 0.0)
                extra = "".join(f", {n} {w}" for n, w in ((r.dropped, "dropped"), (r.duplicates, "duplicates removed"),
                                                             (r.out_of_order, "out of order skipped")) if n)
                lines.append(f"  {sid}/{name}: {r.frames} frames over {span:.3f} s{extra}")
        return "\n".join(lines)


@dataclass
class _Source:
    sensor_id: str
    role: str
    description: SensorDescription
    info: dict[str, Any]


class _Builder:
    """Writes frames of several sources into one staged session, keeping order rules and counts."""

    def __init__(self, out: Path, *, name: str | None, sources: Sequence[_Source], importer: str, time_base: str,
                 source_info: dict, force: bool, total: int | None, progress: bool, desc: str) -> None:
        self.importer = importer
        manifest: dict[str, Any] = {"name": name or out.name, "time_base": time_base,
                                    "source": {"importer": importer, **source_info}, "sensors": {}}
        for s in sources:
            manifest["sensors"][s.sensor_id] = s.description.to_manifest(s.role)
        self.manifest = manifest
        self.writer = SessionWriter(out, manifest, force=force, staged=True)
        self.reports = {s.sensor_id: {n: StreamReport() for n in s.description.streams} for s in sources}
        self._labels = {s.sensor_id: str(s.info.get("path", importer)) for s in sources}
        self._last: dict[tuple[str, str], tuple[int, int, int]] = {}
        self._metadata: dict[str, list[dict]] = {s.sensor_id: [] for s in sources}
        self._domains: dict[str, set[str]] = {s.sensor_id: set() for s in sources}
        from tqdm import tqdm

        self._bar = tqdm(total=total, unit="frame", desc=desc, leave=False, disable=None if progress else True)
        workers = max(2, os.cpu_count() or 2)
        self._pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="import-encode")
        self._pending: deque = deque()
        self._max_pending = 2 * workers

    def add(self, sensor_id: str, frame: Frame) -> None:
        rep = self.reports[sensor_id].get(frame.stream)
        if rep is None:
            return
        key = (sensor_id, frame.stream)
        host = int(frame.host_timestamp_us)
        last = self._last.get(key)
        if last is not None:
            lf, ld, lh = last
            if frame.frame_number == lf:
                rep.duplicates += 1
                return
            if frame.frame_number < lf or frame.device_timestamp_us < ld:
                rep.out_of_order += 1
                return
            rep.dropped += frame.frame_number - lf - 1
            host = max(host, lh)
        # encode + write on the pool (PNG encoding releases the GIL), index in arrival order
        future = self._pool.submit(self.writer.write_frame_file, sensor_id, frame.stream, frame.frame_number,
                                   frame.image)
        self._pending.append((future, sensor_id, frame.stream, frame.frame_number, frame.device_timestamp_us, host))
        self._drain(self._max_pending)
        self._last[key] = (frame.frame_number, frame.device_timestamp_us, host)
        rep.frames += 1
        if rep.first_device_us is None:
            rep.first_device_us = frame.device_timestamp_us
        rep.last_device_us = frame.device_timestamp_us
        self._domains[sensor_id].add(frame.clock_domain)
        if frame.metadata:
            self._metadata[sensor_id].append({"stream": frame.stream, "frame_number": frame.frame_number,
                                              "clock_domain": frame.clock_domain, **frame.metadata})

    def _drain(self, keep: int) -> None:
        """Index finished frames, in submission order, until at most ``keep`` are in flight."""
        while len(self._pending) > keep or (self._pending and self._pending[0][0].done()):
            future, sid, stream, number, dev, host = self._pending.popleft()
            rel, sha = future.result()
            self.writer.index_frame(sid, stream, number, device_timestamp_us=dev, host_timestamp_us=host, rel=rel,
                                    sha256=sha)
            self._bar.update(1)

    def finish(self, notes: dict[str, Any] | None = None) -> ImportResult:
        self._drain(0)
        self._pool.shutdown()
        self._bar.close()
        sensors = self.writer.manifest["sensors"]
        skipped = {}
        for sid, streams in self.reports.items():
            for name, rep in streams.items():
                st = sensors[sid]["streams"][name]
                st["dropped_frames"] = rep.dropped
                st["duplicate_frames"] = rep.duplicates
                if rep.out_of_order:
                    skipped[f"{sid}/{name}"] = rep.out_of_order
                if rep.frames == 0:
                    raise SessionFormatError(f"{self._labels.get(sid, self.importer)}: stream {name} has no frames "
                                             f"(sensor {sid})")
            clock = dict(sensors[sid].get("clock", {}))
            if self._domains[sid]:
                clock["domains"] = sorted(self._domains[sid])
            sensors[sid]["clock"] = clock
            rows = self._metadata[sid]
            if rows:
                self._write_metadata(sid, rows)
        source = dict(self.writer.manifest["source"])
        if skipped:
            source["skipped_out_of_order"] = skipped
            log.warning("skipped frames whose timestamp or frame number went backwards: %s", skipped)
        if notes:
            source["notes"] = {**source.get("notes", {}), **notes}
        self.writer.update_manifest(sensors=sensors, source=source)
        path = self.writer.close()
        return ImportResult(path, self.importer, self.reports, source.get("notes", {}))

    def _write_metadata(self, sid: str, rows: list[dict]) -> None:
        keys = ["stream", "frame_number", "clock_domain"]
        keys += sorted({k for r in rows for k in r} - set(keys))
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=keys, lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
        atomic_write_text(self.writer.root / sid / "frame_metadata.csv", buf.getvalue())

    def abort(self) -> None:
        for future, *_ in self._pending:
            future.cancel()
        self._pool.shutdown(wait=True)
        self._pending.clear()
        self._bar.close()
        self.writer.abort()


def _file_info(path: Path) -> dict[str, Any]:
    return {"path": str(path.resolve()), "bytes": path.stat().st_size, "sha256": sha256_file(path)}


def _check_id_role(sensor_id: str, role: str, what: str) -> None:
    if not _ID.match(sensor_id):
        raise CaptureError(f"{what}: sensor id {sensor_id!r} must be 1-32 characters of a-z, 0-9, _")
    if role not in ROLES:
        raise CaptureError(f"{what}: role {role!r} must be one of {', '.join(ROLES)}")


def _run(builder: _Builder, feeds: Iterable[tuple[str, Iterable[Frame]]],
         notes: dict | Callable[[], dict] | None = None) -> ImportResult:
    """Feed every frame, then finish (``notes`` may be a function, called after the last frame)."""
    try:
        for sid, frames in feeds:
            for frame in frames:
                builder.add(sid, frame)
        return builder.finish(notes() if callable(notes) else notes)
    except BaseException:
        builder.abort()
        raise


# ============================================================================ RealSense
def import_realsense(files: Sequence[str | os.PathLike], out: str | os.PathLike, *,
                     sensor_ids: Sequence[str] | None = None, roles: Sequence[str] | None = None,
                     streams: Sequence[str] | None = None, time_base: str = "device", name: str | None = None,
                     force: bool = False, progress: bool = False) -> ImportResult:
    """Import one or more RealSense ``.db3`` recordings (one device each) into one session.

    Args:
        files: recordings, one sensor each (e.g. an LQ and an HQ camera recorded side by side).
        out: the session folder to create.
        sensor_ids: one id per file (default: the role, or role + index when roles repeat).
        roles: one role per file, or one for all (default ``lq``).
        streams: which of ``depth`` (always), ``color``, ``ir``, ``ir2`` to import when present (default all).
        time_base: ``"device"`` (frame timestamps) or ``"host"`` (time of arrival when recorded).
        name: session name (default: the folder name).
        force: replace an existing ``out``.
        progress: show a progress bar on stderr.
    """
    from capture.drivers.realsense import open_recording

    out = Path(out)
    files = [Path(f) for f in files]
    if not files:
        raise CaptureError("import realsense: no recording given")
    roles = list(roles or ["lq"])
    if len(roles) == 1:
        roles = roles * len(files)
    if len(roles) != len(files):
        raise CaptureError(f"import realsense: {len(roles)} roles for {len(files)} recordings (give one, or one per file)")
    if sensor_ids is None:
        sensor_ids = [r if roles.count(r) == 1 else f"{r}{roles[:i].count(r)}" for i, r in enumerate(roles)]
    sensor_ids = list(sensor_ids)
    if len(sensor_ids) != len(files):
        raise CaptureError(f"import realsense: {len(sensor_ids)} sensor ids for {len(files)} recordings")
    if len(set(sensor_ids)) != len(sensor_ids):
        raise CaptureError(f"import realsense: sensor ids must be unique, got {', '.join(sensor_ids)}")
    for sid, role in zip(sensor_ids, roles):
        _check_id_role(sid, role, "import realsense")
    if time_base not in ("device", "host"):
        raise CaptureError(f"import realsense: time base must be 'device' or 'host', got {time_base!r}")
    check_output_free(out, force=force, what="session folder")
    for f in files:
        if not f.is_file():
            raise SessionFormatError(f"{f}: no such file" if not f.exists() else f"{f}: not a file")
    recordings = []
    try:
        for f in files:
            recordings.append(open_recording(f, streams=tuple(streams) if streams else None))
        sources = [_Source(sid, role, rec.description, {"path": rec.path})
                   for sid, role, rec in zip(sensor_ids, roles, recordings)]
        total = sum(rec.expected_count(n) for rec in recordings for n in rec.source.selected)
        info = {"files": [{**_file_info(rec.path), "sensor": sid} for sid, rec in zip(sensor_ids, recordings)],
                "sdk": "pyrealsense2 playback (not real time)"}
        builder = _Builder(out, name=name, sources=sources, importer="realsense", time_base=time_base,
                           source_info=info, force=force, total=total, progress=progress, desc="import realsense")
        return _run(builder, ((sid, rec.frames()) for sid, rec in zip(sensor_ids, recordings)),
                    lambda: {sid: {"host_timestamps": rec.host_source, **rec.notes}
                             for sid, rec in zip(sensor_ids, recordings)})
    finally:
        for rec in recordings:
            rec.close()


# ============================================================================ Azure Kinect
def import_azure_kinect(file: str | os.PathLike, out: str | os.PathLike, *, sensor_id: str = "hq", role: str = "hq",
                        streams: Sequence[str] = ("depth", "color", "ir"), name: str | None = None,
                        force: bool = False, progress: bool = False) -> ImportResult:
    """Import an Azure Kinect ``.mkv`` recording (depth, colour, IR, factory calibration) into a session.

    Device and host timestamp columns both hold the device timestamp (the file has no host
    times); ``time_base`` is ``device``."""
    from capture.drivers.azure_kinect import open_mkv

    out, file = Path(out), Path(file)
    _check_id_role(sensor_id, role, "import azure-kinect")
    check_output_free(out, force=force, what="session folder")
    rec = open_mkv(file, streams=tuple(streams))
    info = {"files": [{**_file_info(file), "sensor": sensor_id}], "reader": "PyAV (FFmpeg Matroska demuxer)",
            "host_timestamps": "copy of the device timestamps (the recording has no host times)"}
    builder = _Builder(out, name=name, sources=[_Source(sensor_id, role, rec.description, {"path": file})],
                       importer="azure-kinect",
                       time_base="device", source_info=info, force=force, total=None, progress=progress,
                       desc="import azure-kinect")
    return _run(builder, [(sensor_id, rec.frames())], {sensor_id: rec.notes})


# ============================================================================ TUM RGB-D
def import_tum(folder: str | os.PathLike, out: str | os.PathLike, *, sensor_id: str = "lq", role: str = "lq",
               intrinsics: Intrinsics | None = None, depth_scale: float = 5000.0, fps: float = 30.0,
               with_color: bool = True, name: str | None = None, force: bool = False,
               progress: bool = False) -> ImportResult:
    """Import a TUM RGB-D folder (``rgb.txt``, ``depth.txt``, PNGs; depth / ``depth_scale`` = metres)."""
    from capture.drivers.tum import open_tum

    out, folder = Path(out), Path(folder)
    _check_id_role(sensor_id, role, "import tum")
    check_output_free(out, force=force, what="session folder")
    tum = open_tum(folder, intrinsics=intrinsics, depth_scale=depth_scale, fps=fps, with_color=with_color)
    info = {"files": [{"path": str(folder.resolve()), "sensor": sensor_id}],
            "host_timestamps": "TUM timestamps (both columns)", "depth_scale_counts_per_m": depth_scale}
    builder = _Builder(out, name=name, sources=[_Source(sensor_id, role, tum.description, {"path": folder})],
                       importer="tum",
                       time_base="host", source_info=info, force=force,
                       total=sum(tum.count(s) for s in tum.lists), progress=progress, desc="import tum")
    return _run(builder, [(sensor_id, tum.frames())])
