"""The denoised-output folder that ``depthbench methods run`` writes, and its reader.

Layout::

    OUT/
      denoised.json         what made it: method name, version, key, parameters; the dataset's
                            name, path and checksum; depth unit; frames table checksum
      frames.csv            index,file,sha256: one row per frame of the aligned dataset
      depth/<index>.png     denoised depth, uint16 in ``depth_unit_m`` (the dataset's), 0 = none

The depth convention is the session's: uint16 counts of ``depth_unit_m`` metres, 0 = no depth.
The folder is built under a temporary name and published complete (never half-written), and an
existing output is replaced only with ``force``.
"""
from __future__ import annotations

import csv
import io
import json
import os
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from depthbench import frames as codec
from depthbench.fsutil import atomic_write_json, read_json, safe_join, sha256_bytes, staged_directory
from methods.base import Denoiser
from methods.errors import MethodError

FORMAT = "depthbench.denoised"
FORMAT_VERSION = "1.0"
MANIFEST = "denoised.json"
COLUMNS = ("index", "file", "sha256")


class DenoisedWriter:
    """Writes a denoised-output folder (staged; published by :meth:`close`)."""

    def __init__(self, root: str | os.PathLike, method: Denoiser, *, dataset_checksum: str, dataset_name: str,
                 dataset_path: str, depth_unit_m: float, force: bool = False) -> None:
        self._stage = staged_directory(root, force=force, what="denoised output")
        self.root = self._stage.__enter__()
        self.final_root = Path(root)
        self.depth_unit_m = float(depth_unit_m)
        self.meta = {
            "format": FORMAT, "format_version": FORMAT_VERSION,
            "method": method.name, "version": method.version, "key": method.key,
            "params": json.loads(json.dumps(method.params)), "learned": bool(method.learned),
            "dataset": {"name": dataset_name, "path": dataset_path, "checksum": dataset_checksum},
            "depth_unit_m": self.depth_unit_m,
        }
        self.rows: list[dict] = []
        (self.root / "depth").mkdir()

    def add(self, index: int, depth_m: np.ndarray) -> None:
        """Write the denoised depth ``(H, W)`` float32 metres (NaN = none) of aligned frame ``index``."""
        data = codec.encode_depth_png(depth_m, unit_m=self.depth_unit_m, params=codec.PNG_LEVEL1,
                                      where=f"frame {index}", error=MethodError)
        rel = f"depth/{index:06d}.png"
        self.rows.append({"index": int(index), "file": rel, "sha256": codec.write_frame_file(self.root / rel, data)})

    def close(self, *, seconds: float | None = None) -> Path:
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=list(COLUMNS), lineterminator="\n")
        w.writeheader()
        w.writerows(self.rows)
        text = buf.getvalue()
        (self.root / "frames.csv").write_text(text)
        self.meta.update(frames="frames.csv", frames_sha256=sha256_bytes(text.encode()), n_frames=len(self.rows),
                         created_utc=datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"))
        if seconds is not None:
            self.meta["seconds"] = round(float(seconds), 3)
        atomic_write_json(self.root / MANIFEST, self.meta)
        self._stage.__exit__(None, None, None)
        self.root = self.final_root
        return self.final_root

    def abort(self, exc: BaseException) -> None:
        try:
            self._stage.__exit__(type(exc), exc, None)
        except BaseException:  # noqa: BLE001 - the stage re-raises what it was given
            pass


class DenoisedOutput:
    """A denoised-output folder opened for reading (checks format and checksums)."""

    def __init__(self, root: str | os.PathLike) -> None:
        self.root = Path(root)
        path = self.root / MANIFEST
        self.meta = read_json(path, error=MethodError, missing=" (not a denoised output)")
        if not isinstance(self.meta, dict) or self.meta.get("format") != FORMAT:
            raise MethodError(f"{path}: 'format' must be {FORMAT!r}")
        if str(self.meta.get("format_version", "")).split(".")[0] != FORMAT_VERSION.split(".")[0]:
            raise MethodError(f"{path}: unknown format version {self.meta.get('format_version')!r}")
        frames = self.root / "frames.csv"
        try:
            text = frames.read_text()
        except FileNotFoundError:
            raise MethodError(f"{frames}: missing") from None
        if sha256_bytes(text.encode()) != self.meta.get("frames_sha256"):
            raise MethodError(f"{frames}: checksum mismatch with {MANIFEST}")
        self.rows = list(csv.DictReader(io.StringIO(text)))
        self._by_index = {int(r["index"]): r for r in self.rows}
        self.depth_unit_m = float(self.meta["depth_unit_m"])

    @property
    def key(self) -> str:
        return self.meta["key"]

    @property
    def dataset_checksum(self) -> str:
        return self.meta["dataset"]["checksum"]

    def __len__(self) -> int:
        return len(self.rows)

    def depth(self, index: int) -> np.ndarray:
        """Denoised depth of aligned frame ``index``: ``(H, W)`` float32 metres, NaN = none."""
        row = self._by_index.get(int(index))
        if row is None:
            raise MethodError(f"{self.root}: no frame {index}")
        path = safe_join(self.root, row["file"], source=self.root / "frames.csv", error=MethodError)
        data = codec.read_frame_bytes(path, sha256=row["sha256"], table="frames.csv", what="denoised depth file",
                                      error=MethodError)
        return codec.decode_depth_png(data, unit_m=self.depth_unit_m, where=path, error=MethodError)
