"""Repair a session folder that a crash (or a full disk) left inconsistent.

What a killed recorder can leave, and what :func:`repair` does about it:

* a partial last line in a ``frames.csv`` (power loss; a killed process writes whole rows)
  -> truncated;
* index rows whose frame file is missing, has another checksum or is not a complete
  PNG/JPEG, or that break the order rules -> removed;
* frame files that no row indexes (written but not yet indexed), temporary files
  (``.NAME.tmp``, ``.session.json.*.tmp``) and the recorder's reserve file -> deleted;
* ``session.json`` -> ``checksums`` of every frames table recomputed, ``dropped_frames``
  recomputed per stream from the index, ``status`` set to ``"repaired"``.

A session that needs none of this is left untouched. Nothing outside the session's own
folders is ever deleted: paths read from ``frames.csv`` go through :func:`safe_join`.
"""
from __future__ import annotations

import csv
import io
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

from capture.errors import SessionFormatError
from capture.recorder import RESERVE_NAME, missing_between
from capture.session import (FRAMES_COLUMNS, MANIFEST, image_structure_problem, open_session, validate_manifest)
from depthbench.errors import UnsafePathError
from depthbench.fsutil import atomic_write_bytes, atomic_write_json, read_json, safe_join, sha256_bytes

_SHA = re.compile(r"^[0-9a-f]{64}$")


@dataclass
class RepairResult:
    """What :func:`repair` found and did (or would do with ``dry_run``)."""

    path: Path
    changed: bool = False
    status_before: str = ""
    status_after: str = ""
    rows_kept: int = 0
    rows_removed: list[str] = field(default_factory=list)      # "lq/frames.csv line 12: file missing"
    partial_bytes_truncated: int = 0
    files_removed: list[str] = field(default_factory=list)     # relative paths
    dropped_frames: dict[str, int] = field(default_factory=dict)

    def summary(self) -> str:
        if not self.changed:
            return f"{self.path}: nothing to repair ({self.rows_kept} frames, status {self.status_before})"
        return (f"{self.path}: kept {self.rows_kept} frames, removed {len(self.rows_removed)} index rows and "
                f"{len(self.files_removed)} stray files, truncated {self.partial_bytes_truncated} bytes of a partial "
                f"line; status {self.status_before} -> {self.status_after}")


def repair(path: str | os.PathLike, *, dry_run: bool = False) -> RepairResult:
    """Bring a crashed session folder back to a valid state (see the module docstring).

    Raises :class:`SessionFormatError` when there is nothing to rebuild from (no folder, no
    readable ``session.json``) or when the result still does not validate."""
    root = Path(path)
    manifest_path = root / MANIFEST
    if not root.is_dir():
        raise SessionFormatError(f"{root}: not a session folder (does not exist or is not a folder)")
    manifest = read_json(manifest_path, error=SessionFormatError, missing="; a session cannot be rebuilt without it",
                         invalid_note="; cannot repair")
    validate_manifest(manifest, manifest_path)
    result = RepairResult(root, status_before=manifest.get("status", "complete"))
    new_tables: dict[Path, bytes] = {}
    keep_files: set[Path] = set()
    for sid, sensor in manifest["sensors"].items():
        table_path = _safe(root, sensor["frames"], manifest_path)
        data, kept = _clean_table(root, sid, sensor, table_path, result)
        keep_files |= kept
        if not table_path.exists() or table_path.read_bytes() != data:
            new_tables[table_path] = data
        _count_drops(sid, sensor, data, result)
    stray = _stray_files(root, manifest, keep_files)
    result.files_removed = sorted(str(p.relative_to(root)) for p in stray)
    checksums = {s["frames"]: sha256_bytes(new_tables.get(_safe(root, s["frames"], manifest_path))
                                           or _safe(root, s["frames"], manifest_path).read_bytes())
                 for s in manifest["sensors"].values()}
    counts_changed = any(manifest["sensors"][k.split("/")[0]]["streams"][k.split("/")[1]].get("dropped_frames") != v
                         for k, v in result.dropped_frames.items())
    result.changed = bool(new_tables or stray or result.status_before == "recording"
                          or manifest.get("checksums") != checksums or counts_changed)
    result.status_after = "repaired" if result.changed else result.status_before
    if not result.changed or dry_run:
        return result
    for table_path, data in new_tables.items():
        atomic_write_bytes(table_path, data)
    for p in stray:
        p.unlink(missing_ok=True)
    for key, n in result.dropped_frames.items():
        sid, stream = key.split("/")
        manifest["sensors"][sid]["streams"][stream]["dropped_frames"] = n
    manifest["checksums"] = checksums
    manifest["status"] = "repaired"
    atomic_write_json(manifest_path, manifest)
    open_session(root, verify="full")  # the repaired session must read back completely
    return result


def _safe(root: Path, rel: str, source: Path) -> Path:
    try:
        return safe_join(root, rel, source=source)
    except UnsafePathError as exc:
        raise SessionFormatError(str(exc)) from None


def _clean_table(root: Path, sid: str, sensor: dict, table_path: Path, result: RepairResult) -> tuple[bytes, set[Path]]:
    """The frames table with only good rows, and the frame files those rows keep."""
    header = ",".join(FRAMES_COLUMNS) + "\n"
    raw = table_path.read_bytes() if table_path.exists() else b""
    cut = raw.rfind(b"\n") + 1
    result.partial_bytes_truncated += len(raw) - cut
    text = raw[:cut].decode("utf-8", errors="replace")
    lines = text.splitlines(keepends=True)
    if lines and lines[0] != header:
        raise SessionFormatError(f"{table_path}: header must be {header.strip()}; cannot repair a table without it")
    rel_table = str(table_path.relative_to(root.resolve())) if table_path.is_absolute() else str(table_path)
    out, kept = [header], set()
    last: dict[str, tuple[int, int, int]] = {}
    for line_no, line in enumerate(lines[1:], start=2):
        row = next(csv.reader(io.StringIO(line)), [])
        problem, path = _row_problem(root, sensor, row, table_path, last)
        if problem:
            result.rows_removed.append(f"{rel_table} line {line_no}: {problem}")
            continue
        out.append(line)
        kept.add(path)
        last[row[0]] = (int(row[1]), int(row[2]), int(row[3]))
        result.rows_kept += 1
    return "".join(out).encode(), kept


def _row_problem(root: Path, sensor: dict, row: list[str], table_path: Path,
                 last: dict[str, tuple[int, int, int]]) -> tuple[str | None, Path | None]:
    if len(row) != len(FRAMES_COLUMNS):
        return f"{len(row)} fields instead of {len(FRAMES_COLUMNS)}", None
    stream, fn, dev, host, rel, sha = row
    if stream not in sensor["streams"]:
        return f"unknown stream {stream!r}", None
    try:
        fn, dev, host = int(fn), int(dev), int(host)
    except ValueError:
        return "frame number or timestamp is not an integer", None
    if not _SHA.match(sha):
        return "malformed sha256", None
    if stream in last:
        lf, ld, lh = last[stream]
        if fn <= lf or dev < ld or host < lh:
            return f"frame {fn} out of order after frame {lf}", None
    try:
        path = safe_join(root, rel, source=table_path)
    except UnsafePathError:
        return f"path {rel!r} escapes the session folder", None
    try:
        data = path.read_bytes()
    except (FileNotFoundError, IsADirectoryError):
        return f"frame file {rel} is missing", None
    if sha256_bytes(data) != sha:
        return f"frame file {rel} does not match its checksum", None
    problem = image_structure_problem(data)
    if problem:
        return f"frame file {rel}: {problem}", None
    return None, path


def _count_drops(sid: str, sensor: dict, table: bytes, result: RepairResult) -> None:
    rows = list(csv.reader(io.StringIO(table.decode())))[1:]
    for stream, info in sensor["streams"].items():
        seq = [(int(r[1]), int(r[2])) for r in rows if r[0] == stream]
        period = 1e6 / float(info["fps"])
        result.dropped_frames[f"{sid}/{stream}"] = sum(
            missing_between(a[0], a[1], b[0], b[1], period) for a, b in zip(seq, seq[1:]))


def _stray_files(root: Path, manifest: dict, keep: set[Path]) -> list[Path]:
    """Temporary files, the recorder's reserve, and unindexed files in the sessions' frame folders."""
    stray = [p for p in root.iterdir() if p.is_file() and (p.name == RESERVE_NAME or
                                                          (p.name.startswith(".") and p.name.endswith(".tmp")))]
    root_resolved = root.resolve()
    for sid, sensor in manifest["sensors"].items():
        table_dir = _safe(root, sensor["frames"], root / MANIFEST).parent
        stray += [p for p in table_dir.iterdir() if p.is_file() and p.name.startswith(".") and p.name.endswith(".tmp")]
        for stream in sensor["streams"]:
            folder = root_resolved / sid / stream
            if folder.is_dir():
                stray += [p for p in folder.iterdir() if p.is_file() and p.resolve() not in keep]
    return sorted(set(stray))
