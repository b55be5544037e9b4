"""The recorder: every sensor of a rig at once into a crash-safe session folder.

Threads::

    driver.read() --reader thread per sensor--> bounded queue --N encoder threads--> frame file
                                                                 (PNG encode, temp name + rename)
                                                 per-stream sequencer --> frames.csv row (one write)

* A frame is written completely (temporary name, then rename) before its row is appended to
  the sensor's ``frames.csv``; rows are appended in frame order per stream with a single
  ``write`` each. A process killed at any moment therefore leaves a session that
  :func:`capture.session.open_session` reads up to its last indexed frame; what was in flight
  (queued, being encoded, written but not yet indexed) is lost, and ``depthbench capture repair``
  removes its leftovers.
* Per stream the reader counts dropped frames (gaps in the device frame counter, or device
  intervals over 1.5 frame periods), removes and counts duplicates (a frame number seen again)
  and frames whose timestamps go backwards. When the queue is full the frame is dropped and
  counted as a writer drop (also part of ``dropped_frames``): the sensor is never blocked.
* When the queue is over an eighth full the encoders write PNGs uncompressed (lossless, same
  pixels, larger) until it has drained: CPU, not the disk, is the bottleneck on small machines.
* A full disk (ENOSPC) stops recording: the reserve file made at the start is deleted so the
  manifest can still be written, the session is closed readable and :class:`RecordingError`
  says what happened.

The counting rules are pure functions (:func:`missing_between`, :class:`StreamCounter`) shared
with :mod:`capture.repair`.
"""
from __future__ import annotations

import contextlib
import errno
import os
import queue
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

from capture.drivers.base import (Driver, Frame, SensorDescription, driver_class, host_clock_us,
                                  host_clock_utc_offset_us)
from capture.errors import DeviceError, RecordingError, RigError
from capture.rig import Rig
from capture.session import SessionWriter, check_disk_space
from depthbench.errors import DepthbenchError
from depthbench.fsutil import check_output_free

RESERVE_NAME = ".recorder-reserve"
RESERVE_BYTES = 4 << 20
_MANIFEST_EVERY_S = 2.0


# ----------------------------------------------------------------------------- counting (pure)
def missing_between(prev_number: int, prev_device_us: int, number: int, device_us: int, period_us: float) -> int:
    """Frames missing between two consecutive delivered frames of one stream.

    The larger of the gap in the frame counter and, when the device interval exceeds 1.5
    periods, the number of whole periods skipped (catches counters that do not count drops)."""
    by_counter = max(0, number - prev_number - 1)
    dt = device_us - prev_device_us
    by_time = max(0, round(dt / period_us) - 1) if period_us > 0 and dt > 1.5 * period_us else 0
    return max(by_counter, by_time)


@dataclass
class StreamStats:
    """Counters of one stream. ``dropped`` includes ``writer_dropped``."""

    frames: int = 0          # frames indexed in the session
    dropped: int = 0         # missing frames (device gaps, long intervals, writer drops)
    duplicates: int = 0      # frames with a frame number already seen, removed
    rejected: int = 0        # frames with a frame number or timestamp going backwards, removed
    writer_dropped: int = 0  # received but not written: the queue was full
    lost_in_flight: int = 0  # received but not indexed when recording stopped on an error
    fast_encoded: int = 0    # frames written as uncompressed PNG because the writer was falling behind
    bytes: int = 0           # encoded bytes written


class StreamCounter:
    """Classifies each arriving frame of one stream: accept, duplicate or out of order; counts drops."""

    def __init__(self, period_us: float) -> None:
        self.period_us = period_us
        self.last: tuple[int, int, int] | None = None  # frame number, device µs, host µs
        self.stats = StreamStats()

    def classify(self, number: int, device_us: int, host_us: int) -> str:
        """``"accept"``, ``"duplicate"`` or ``"rejected"``; updates drop/duplicate counts."""
        if self.last is not None:
            ln, ld, lh = self.last
            if number == ln:
                self.stats.duplicates += 1
                return "duplicate"
            if number < ln or device_us < ld or host_us < lh:
                self.stats.rejected += 1
                return "rejected"
            self.stats.dropped += missing_between(ln, ld, number, device_us, self.period_us)
        self.last = (number, device_us, host_us)
        return "accept"


# ----------------------------------------------------------------------------- results
@dataclass
class RecordResult:
    """What :func:`record` did.

    Attributes:
        path: the session folder.
        status: the session's final status (``"complete"``, or ``"recording"`` if even the
            manifest could not be finalised: run ``depthbench capture repair``).
        stopped_by: ``"time"``, ``"sources ended"``, ``"interrupted"``, ``"disk full"``, ``"error"``.
        wall_s: seconds from the first frame expected to the stop.
        streams: ``"sensor/stream"`` -> :class:`StreamStats`.
        message: one line for the user.
    """

    path: Path
    status: str
    stopped_by: str
    wall_s: float
    streams: dict[str, StreamStats] = field(default_factory=dict)
    message: str = ""

    @property
    def frames(self) -> int:
        return sum(s.frames for s in self.streams.values())

    @property
    def bytes(self) -> int:
        return sum(s.bytes for s in self.streams.values())

    @property
    def frames_per_s(self) -> float:
        return self.frames / self.wall_s if self.wall_s > 0 else 0.0

    @property
    def mb_per_s(self) -> float:
        return self.bytes / 1e6 / self.wall_s if self.wall_s > 0 else 0.0

    @property
    def writer_dropped(self) -> int:
        return sum(s.writer_dropped for s in self.streams.values())

    @property
    def fast_encoded(self) -> int:
        return sum(s.fast_encoded for s in self.streams.values())


@dataclass
class _Job:
    sensor: str
    stream: str
    seq: int
    frame: Frame


class _Sequencer:
    """Indexes finished frames in arrival order per stream (encoders finish out of order)."""

    def __init__(self, writer: SessionWriter) -> None:
        self.writer = writer
        self.lock = threading.Lock()
        self.next: dict[tuple[str, str], int] = {}
        self.pending: dict[tuple[str, str], dict[int, tuple | None]] = {}

    def done(self, key: tuple[str, str], seq: int, row: tuple | None, stats: StreamStats) -> None:
        """``row`` = (frame_number, dev, host, rel, sha, nbytes), or None for a frame that failed."""
        with self.lock:
            pending = self.pending.setdefault(key, {})
            pending[seq] = row
            nxt = self.next.get(key, 0)
            while nxt in pending:
                r = pending.pop(nxt)
                if r is not None:
                    self.writer.index_frame(key[0], key[1], *r[:5])
                    stats.frames += 1
                    stats.bytes += r[5]
                nxt += 1
            self.next[key] = nxt


# ----------------------------------------------------------------------------- the recorder
class _Recorder:
    def __init__(self, rig: Rig, out: Path, *, seconds: float | None, force: bool, writers: int, buffer_s: float,
                 fsync: bool, progress: TextIO | None, progress_every_s: float, adaptive: bool) -> None:
        self.rig, self.out, self.seconds, self.force, self.adaptive = rig, out, seconds, force, adaptive
        self.n_writers, self.buffer_s, self.fsync = writers, buffer_s, fsync
        self.progress, self.progress_every_s = progress, progress_every_s
        self.drivers: dict[str, Driver] = {}
        self.descriptions: dict[str, SensorDescription] = {}
        self.counters: dict[tuple[str, str], StreamCounter] = {}
        self.clock_domains: dict[str, str] = {}
        self.stop = threading.Event()
        self.ended: set[str] = set()
        self.fatal: tuple[str, str] | None = None  # (stopped_by, message)
        self.fatal_lock = threading.Lock()
        self.seq: dict[tuple[str, str], int] = {}
        self.writer: SessionWriter | None = None

    # -- phase 1: check everything before touching anything
    def open_drivers(self) -> None:
        check_output_free(self.out, force=self.force, what="session folder")
        classes = {}
        where = f"{self.rig.path}: " if self.rig.path else ""
        for cfg in self.rig.sensors:
            try:
                cls = driver_class(cfg.driver)
            except DeviceError as exc:
                raise DeviceError(f"{where}sensor {cfg.id!r}: {exc}") from None
            try:
                cls.check_config(cfg)
            except RigError as exc:
                raise RigError(f"{where}{exc}") from None
            classes[cfg.id] = cls
        try:
            for cfg in self.rig.sensors:
                drv = classes[cfg.id](cfg)
                self.drivers[cfg.id] = drv
                try:
                    desc = drv.open()
                except DepthbenchError:
                    raise
                except Exception as exc:  # an SDK error a driver did not translate: still one line
                    raise DeviceError(f"sensor {cfg.label}: {type(exc).__name__}: {_one_line(exc)}") from None
                if not desc.streams:
                    raise DeviceError(f"sensor {cfg.label}: the device delivers no streams")
                self.descriptions[cfg.id] = desc
                for name, st in desc.streams.items():
                    self.counters[(cfg.id, name)] = StreamCounter(st.period_us)
        except BaseException:
            self.close_drivers()
            raise

    def close_drivers(self) -> None:
        for drv in self.drivers.values():
            with contextlib.suppress(Exception):
                drv.close()

    def manifest(self) -> dict:
        sensors = {cfg.id: self.descriptions[cfg.id].to_manifest(cfg.role) for cfg in self.rig.sensors}
        for cfg in self.rig.sensors:
            if cfg.sync:
                sensors[cfg.id].setdefault("clock", {})["sync"] = dict(cfg.sync)
        m = {"name": self.rig.name, "time_base": self.rig.time_base,
             "source": {"producer": "depthbench capture record",
                        "rig": str(self.rig.path) if self.rig.path else None,
                        "drivers": {c.id: c.driver for c in self.rig.sensors},
                        "host_clock": {"name": "CLOCK_MONOTONIC", "unit": "us",
                                       "utc_offset_us": host_clock_utc_offset_us()}},
             "sensors": sensors}
        if self.rig.extrinsics:
            m["extrinsics"] = [dict(e) for e in self.rig.extrinsics]
        if self.rig.clock_facts:
            m["clock_facts"] = dict(self.rig.clock_facts)
        return m

    # -- phase 2: record
    def run(self) -> RecordResult:
        self.writer = SessionWriter(self.out, self.manifest(), force=self.force, staged=False, fsync=self.fsync)
        reserve = self.writer.root / RESERVE_NAME
        _make_reserve(reserve)
        total_fps = sum(st.fps for d in self.descriptions.values() for st in d.streams.values())
        self.queue: queue.Queue[_Job | None] = queue.Queue(maxsize=max(8, int(total_fps * self.buffer_s)))
        # Falling behind (queue over an eighth full, ~0.1 s): encode PNGs uncompressed until it drains.
        self.fast_above = max(2, self.queue.maxsize // 8) if self.adaptive else self.queue.maxsize + 1
        self.behind = False
        self.sequencer = _Sequencer(self.writer)
        encoders = [threading.Thread(target=self._encode_loop, name=f"encoder-{i}", daemon=True)
                    for i in range(self.n_writers)]
        readers = [threading.Thread(target=self._read_loop, args=(sid,), name=f"reader-{sid}", daemon=True)
                   for sid in self.drivers]
        for t in encoders + readers:
            t.start()
        t0 = time.monotonic()
        stopped_by = self._wait(t0)
        wall = time.monotonic() - t0
        self.stop.set()
        self.close_drivers()
        for t in readers:
            t.join()
        for _ in encoders:
            self.queue.put(None)
        for t in encoders:
            t.join()
        if stopped_by == "disk full":
            with contextlib.suppress(OSError):
                reserve.unlink()
        status = self._finish()
        with contextlib.suppress(OSError):
            reserve.unlink()
        if self.progress:
            self._show(wall, final=True)
        result = RecordResult(self.writer.final_root, status, stopped_by, wall,
                              {f"{k[0]}/{k[1]}": c.stats for k, c in self.counters.items()})
        result.message = self._message(result)
        return result

    def _wait(self, t0: float) -> str:
        last_show = last_manifest = t0
        try:
            while True:
                time.sleep(0.05)
                now = time.monotonic()
                if self.fatal is not None:
                    return self.fatal[0]
                if self.seconds is not None and now - t0 >= self.seconds:
                    return "time"
                if len(self.ended) == len(self.drivers):
                    return "sources ended"
                if self.progress and now - last_show >= self.progress_every_s:
                    self._show(now - t0)
                    last_show = now
                if now - last_manifest >= _MANIFEST_EVERY_S:
                    self._write_counts()
                    last_manifest = now
        except KeyboardInterrupt:
            return "interrupted"

    def _read_loop(self, sid: str) -> None:
        drv = self.drivers[sid]
        try:
            while not self.stop.is_set():
                batch = drv.read(timeout_s=0.2)
                if batch is None:
                    break
                for frame in batch:
                    self._accept(sid, frame)
        except Exception as exc:  # a device failing stops the recording, keeping what was written
            if not self.stop.is_set():
                self._set_fatal("error", f"sensor {sid}: {_one_line(exc)}")
        finally:
            self.ended.add(sid)

    def _accept(self, sid: str, frame: Frame) -> None:
        key = (sid, frame.stream)
        counter = self.counters.get(key)
        if counter is None:
            raise DeviceError(f"delivered a frame of stream {frame.stream!r}, which it did not describe")
        self.clock_domains.setdefault(sid, frame.clock_domain)
        if counter.classify(int(frame.frame_number), int(frame.device_timestamp_us),
                            int(frame.host_timestamp_us)) != "accept":
            return
        seq = self.seq.get(key, 0)
        try:
            self.queue.put_nowait(_Job(sid, frame.stream, seq, frame))
        except queue.Full:
            counter.stats.writer_dropped += 1
            counter.stats.dropped += 1
            return
        self.seq[key] = seq + 1

    def _encode_loop(self) -> None:
        while True:
            job = self.queue.get()
            if job is None:
                return
            key = (job.sensor, job.stream)
            stats = self.counters[key].stats
            if self.fatal is not None:  # stopping on an error: what is still queued is lost
                stats.lost_in_flight += 1
                self.sequencer.done(key, job.seq, None, stats)
                continue
            f = job.frame
            fast = self._fast_mode()
            try:
                rel, sha = self.writer.write_frame_file(job.sensor, job.stream, f.frame_number, f.image, fast=fast)
                stats.fast_encoded += fast
                nbytes = (self.writer.root / rel).stat().st_size
                self.sequencer.done(key, job.seq, (f.frame_number, f.device_timestamp_us, f.host_timestamp_us,
                                                   rel, sha, nbytes), stats)
            except OSError as exc:
                stats.lost_in_flight += 1
                full = exc.errno in (errno.ENOSPC, errno.EDQUOT)
                self._set_fatal("disk full" if full else "error",
                                f"{self.out}: {'disk full' if full else 'cannot write'} ({exc.strerror or exc})")
                with contextlib.suppress(Exception):
                    self.sequencer.done(key, job.seq, None, stats)
            except DepthbenchError as exc:  # e.g. a frame of the wrong size from a driver
                stats.lost_in_flight += 1
                self._set_fatal("error", f"sensor {job.sensor}: {_one_line(exc)}")
                self.sequencer.done(key, job.seq, None, stats)

    def _fast_mode(self) -> bool:
        """Uncompressed PNGs from when the queue passes ``fast_above`` until it is (nearly) empty."""
        waiting = self.queue.qsize()
        if waiting > self.fast_above:
            self.behind = True
        elif waiting <= 1:
            self.behind = False
        return self.behind

    def _set_fatal(self, stopped_by: str, message: str) -> None:
        with self.fatal_lock:
            if self.fatal is None:
                self.fatal = (stopped_by, message)

    def _write_counts(self, *, write: bool = True) -> None:
        for (sid, name), c in self.counters.items():
            self.writer.set_stream_counts(sid, name, dropped_frames=c.stats.dropped, duplicate_frames=c.stats.duplicates,
                                          writer_dropped_frames=c.stats.writer_dropped)
        for sid, domain in self.clock_domains.items():
            self.writer.manifest["sensors"][sid].setdefault("clock", {})["domain"] = domain
        if write:
            with contextlib.suppress(OSError):  # best effort while recording; the final write reports
                self.writer.write_manifest()

    def _finish(self) -> str:
        self._write_counts(write=False)
        try:
            self.writer.close("complete")
            return "complete"
        except OSError as exc:
            self._set_fatal("disk full" if exc.errno == errno.ENOSPC else "error",
                            f"{self.out}: cannot finalise session.json ({exc.strerror or exc})")
            return "recording"

    def _show(self, elapsed: float, *, final: bool = False) -> None:
        parts = []
        for (sid, name), c in self.counters.items():
            fps = c.stats.frames / elapsed if elapsed > 0 else 0.0
            extra = f" dup {c.stats.duplicates}" if c.stats.duplicates else ""
            parts.append(f"{sid}/{name} {fps:5.1f} fps drop {c.stats.dropped}{extra}")
        mb = sum(c.stats.bytes for c in self.counters.values()) / 1e6
        line = (f"rec {elapsed:6.1f}s | " + " | ".join(parts)
                + f" | queue {self.queue.qsize()}/{self.queue.maxsize} | {mb / max(elapsed, 1e-9):.1f} MB/s")
        tty = self.progress.isatty() if hasattr(self.progress, "isatty") else False
        if tty and not final:
            self.progress.write("\r" + line[:250] + "\x1b[K")
        else:
            self.progress.write(("\r" if tty else "") + line + "\n")
        self.progress.flush()

    def _message(self, r: RecordResult) -> str:
        drops = sum(s.dropped for s in r.streams.values())
        dups = sum(s.duplicates for s in r.streams.values())
        base = (f"{r.path}: {r.frames} frames in {r.wall_s:.1f} s ({r.frames_per_s:.1f} frames/s, {r.mb_per_s:.1f} MB/s), "
                f"{drops} dropped ({r.writer_dropped} by the writer), {dups} duplicates removed"
                + (f", {r.fast_encoded} frames written uncompressed to keep up" if r.fast_encoded else ""))
        if self.fatal is not None:
            fix = ("; run 'depthbench capture repair' on it" if r.status != "complete" else "")
            return (f"{self.fatal[1]}: recording stopped after {r.wall_s:.1f} s; the session keeps {r.frames} frames "
                    f"and is readable{fix}")
        return base


def _make_reserve(path: Path) -> None:
    """A file holding a little disk space, deleted on ENOSPC so the manifest can still be written."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            try:
                os.posix_fallocate(fd, 0, RESERVE_BYTES)
            except (OSError, AttributeError):
                os.write(fd, b"\0" * RESERVE_BYTES)
        finally:
            os.close(fd)
    except OSError as exc:
        with contextlib.suppress(OSError):
            path.unlink()
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            raise RecordingError(f"{path.parent}: disk full before recording started ({exc.strerror})") from None
        raise


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def default_writers() -> int:
    """Encoder threads: one per core plus one (PNG encoding and file writes release the GIL; the
    extra thread keeps the cores busy while another waits on a write), at least three."""
    return max(3, (os.cpu_count() or 2) + 1)


def record(rig: Rig, out: str | os.PathLike, *, seconds: float | None = None, force: bool = False,
           writers: int | None = None, buffer_s: float = 1.0, fsync: bool = False,
           progress: TextIO | None = None, progress_every_s: float = 1.0, adaptive: bool = True,
           check_space: bool = True) -> RecordResult:
    """Record every sensor of ``rig`` into the session folder ``out``.

    Args:
        rig: from :func:`capture.rig.load_rig`.
        out: session folder to create; an existing non-empty one needs ``force`` (it is then
            replaced once every sensor has opened).
        seconds: stop after this long (wall clock); ``None`` = until every source ends or Ctrl-C.
        writers: encoder threads (default :func:`default_writers`).
        buffer_s: the frame queue holds this many seconds of frames of all streams; beyond it
            frames are dropped and counted as writer drops.
        fsync: fsync every frame and row (survives power loss, slower).
        progress: stream for the live status line (per-stream frame rate and drops), or None.
        adaptive: while the queue is over an eighth full, write PNGs uncompressed (same pixels,
            larger files, ~8x less CPU) so a slow machine keeps up instead of dropping frames.
        check_space: with ``seconds``, refuse (:class:`DiskSpaceError`) when the disk has less free
            space than that many seconds of frames can take (:func:`capture.session.check_disk_space`).

    Returns a :class:`RecordResult`. Raises :class:`RigError`/:class:`DeviceError` before
    anything is written (bad rig, device missing, output exists), and :class:`RecordingError`
    (with ``.result``) when recording stopped on a full disk or a failing device; the session
    is then closed readable with what was written.
    """
    if seconds is not None and not seconds > 0:
        raise RecordingError(f"recording length seconds={seconds}: must be positive")
    if not buffer_s > 0:
        raise RecordingError(f"write-queue length buffer_s={buffer_s}: must be positive (seconds of frames)")
    if writers is not None and writers < 1:
        raise RecordingError(f"encoder threads writers={writers}: must be at least 1")
    rec = _Recorder(rig, Path(out), seconds=seconds, force=force, writers=writers or default_writers(),
                    buffer_s=buffer_s, fsync=fsync, progress=progress, progress_every_s=progress_every_s,
                    adaptive=adaptive)
    rec.open_drivers()
    try:
        if check_space and seconds is not None:
            check_disk_space(out, [st for d in rec.descriptions.values() for st in d.streams.values()], seconds)
        result = rec.run()
    except BaseException:
        rec.stop.set()
        rec.close_drivers()
        raise
    if rec.fatal is not None:
        err = RecordingError(result.message)
        err.result = result
        raise err
    return result


__all__ = ["RecordResult", "StreamCounter", "StreamStats", "default_writers", "missing_between", "record"]
