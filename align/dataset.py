"""The aligned dataset: LQ frames with the HQ depth warped onto the LQ image plane.

Layout (documented in ``data_manifests/aligned.md``)::

    ALIGNED/
      aligned.json            fitted model and metadata (schemas/aligned.schema.json)
      frames.csv              one row per aligned frame: files and their sha256
      pairs.csv               (optional) every candidate LQ/HQ pair, kept or not, and why
      lq_depth/<i>.png        LQ depth, uint16, depth_unit_m, 0 = none
      lq_color/<i>.png        LQ colour (optional)
      hq_depth/<i>.png        HQ depth warped onto the LQ depth image, uint16, depth_unit_m, 0 = none
      roi/<i>.png             region-of-interest mask M_r, uint8 0/255 (optional)
      truth_depth/<i>.png     noise-free LQ depth (simulated data only), uint16, truth_unit_m

Every reader call returns float32 metres with NaN holes, bool masks, RGB uint8 colour.
"""
from __future__ import annotations

import csv
import io
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from align.errors import AlignedFormatError
from capture.camera import Intrinsics, Transform
from data_manifests import schema_problem
from depthbench import frames as codec
from depthbench.fsutil import atomic_write_json, read_json, safe_join, sha256_bytes, staged_directory

FORMAT = "depthbench.aligned"
FORMAT_VERSION = "1.0"
MANIFEST = "aligned.json"
LAYERS = ("lq_depth", "lq_color", "hq_depth", "roi", "truth_depth")
FRAME_COLUMNS = ("index", "lq_frame", "hq_frame", "lq_timestamp_us") + tuple(
    f"{layer}_{part}" for layer in LAYERS for part in ("file", "sha256"))
TRUTH_UNIT_M = 1e-4
#: The depth layers and their unit: None = the dataset's ``depth_unit_m``.
_DEPTH_UNITS = {"lq_depth": None, "hq_depth": None, "truth_depth": TRUTH_UNIT_M}


@dataclass
class AlignedFrame:
    """One aligned frame. Depths ``(H, W)`` float32 metres, NaN = none."""

    index: int
    lq_depth: np.ndarray
    reference: np.ndarray
    lq_color: np.ndarray | None = None
    roi: np.ndarray | None = None
    truth: np.ndarray | None = None


def _check_meta(meta: dict, where: Path) -> None:
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise AlignedFormatError(f"{where}: 'format' must be {FORMAT!r}")
    version = str(meta.get("format_version", ""))
    if version.split(".")[0] != FORMAT_VERSION.split(".")[0]:
        raise AlignedFormatError(f"{where}: unknown format version {version!r} (this reader understands 1.x)")
    problem = schema_problem("aligned", meta)
    if problem:
        raise AlignedFormatError(f"{where}: {problem}")


class AlignedDataset:
    """An aligned dataset opened for reading."""

    def __init__(self, root: str | os.PathLike) -> None:
        self.root = Path(root)
        self.meta_path = self.root / MANIFEST
        self.meta = read_json(self.meta_path, error=AlignedFormatError, missing=" (not an aligned dataset)")
        _check_meta(self.meta, self.meta_path)
        self.frames_path = self.root / "frames.csv"
        try:
            text = self.frames_path.read_text()
        except FileNotFoundError:
            raise AlignedFormatError(f"{self.frames_path}: missing") from None
        rows = list(csv.DictReader(io.StringIO(text)))
        if rows and tuple(rows[0].keys()) != FRAME_COLUMNS:
            raise AlignedFormatError(f"{self.frames_path}: header must be {','.join(FRAME_COLUMNS)}")
        self.rows = rows
        self.checksum = self.meta["dataset_checksum"]
        if sha256_bytes(text.encode()) != self.meta["frames_sha256"]:
            raise AlignedFormatError(f"{self.frames_path}: checksum mismatch with aligned.json")
        self.lq_intrinsics = Intrinsics.from_dict(self.meta["lq_intrinsics"])
        self.depth_unit_m = float(self.meta["depth_unit_m"])

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def name(self) -> str:
        return self.meta["name"]

    @property
    def sequence(self) -> str:
        return self.meta.get("sequence", self.meta["name"])

    @property
    def simulated(self) -> bool:
        return any(r["truth_depth_file"] for r in self.rows)

    @property
    def time_shift_us(self) -> int:
        return int(self.meta["time_shift_us"])

    @property
    def T_lq_hq(self) -> Transform:
        return Transform.from_list(self.meta["T_lq_hq"])

    def layer_path(self, i: int, layer: str) -> Path | None:
        """The file of ``layer`` of frame ``i`` (inside the dataset folder), ``None`` if the frame has none."""
        rel = self.rows[i][f"{layer}_file"]
        return safe_join(self.root, rel, source=self.frames_path, error=AlignedFormatError) if rel else None

    def check_frame_files(self) -> int:
        """Check that every frame file of every layer is present, a regular file and readable,
        without reading any (for a long job to fail at once rather than at the frame); returns
        the number checked. Raises :class:`AlignedFormatError`."""
        paths = (self.layer_path(i, layer) for i in range(len(self)) for layer in LAYERS)
        return codec.check_frame_files((p for p in paths if p is not None), table=self.frames_path,
                                       error=AlignedFormatError)

    def _layer(self, i: int, layer: str) -> np.ndarray | None:
        """The image of ``layer`` as stored (checked against its sha256 and the LQ image size)."""
        path = self.layer_path(i, layer)
        if path is None:
            return None
        data = codec.read_frame_bytes(path, sha256=self.rows[i][f"{layer}_sha256"], table="frames.csv",
                                      error=AlignedFormatError)
        img = codec.decode_image(data, where=path, error=AlignedFormatError, shape=self.lq_intrinsics.shape)
        if layer in _DEPTH_UNITS:
            codec.check_depth_counts(img, where=path, error=AlignedFormatError)
        return img

    def _depth(self, i: int, layer: str) -> np.ndarray | None:
        img = self._layer(i, layer)
        unit = self.depth_unit_m if _DEPTH_UNITS[layer] is None else float(self.meta.get("truth_unit_m", TRUTH_UNIT_M))
        return None if img is None else codec.decode_depth(img, unit)

    def lq_depth(self, i: int) -> np.ndarray:
        return self._depth(i, "lq_depth")

    def reference(self, i: int) -> np.ndarray:
        """The HQ depth warped onto the LQ image plane (NaN where no reference)."""
        return self._depth(i, "hq_depth")

    def lq_color(self, i: int) -> np.ndarray | None:
        path, img = self.layer_path(i, "lq_color"), self._layer(i, "lq_color")
        return None if img is None else codec.to_rgb(img, where=path, error=AlignedFormatError)

    def roi(self, i: int) -> np.ndarray | None:
        img = self._layer(i, "roi")
        return None if img is None else img > 0

    def truth(self, i: int) -> np.ndarray | None:
        return self._depth(i, "truth_depth")

    def frame(self, i: int) -> AlignedFrame:
        return AlignedFrame(i, self.lq_depth(i), self.reference(i), self.lq_color(i), self.roi(i), self.truth(i))


class AlignedDatasetWriter:
    """Build an aligned dataset in a staged folder; published by :meth:`close`.

    ``meta`` must hold at least ``name``, ``lq_intrinsics`` (dict), ``time_shift_us`` and
    ``T_lq_hq``; the writer fills the format fields and checksums.
    """

    def __init__(self, root: str | os.PathLike, meta: dict, *, force: bool = False, depth_unit_m: float = 1e-4) -> None:
        self._stage = staged_directory(root, force=force, what="aligned dataset")
        self.root = self._stage.__enter__()
        self.final_root = Path(root)
        self.meta = {"format": FORMAT, "format_version": FORMAT_VERSION, "effects": [], **json.loads(json.dumps(meta)),
                     "depth_unit_m": depth_unit_m, "truth_unit_m": TRUTH_UNIT_M}
        self.K = Intrinsics.from_dict(self.meta["lq_intrinsics"])
        self.rows: list[dict] = []
        for layer in LAYERS:
            (self.root / layer).mkdir()

    def _write(self, layer: str, i: int, img: np.ndarray | None) -> tuple[str, str]:
        if img is None:
            return "", ""
        if img.shape[:2] != self.K.shape:
            raise AlignedFormatError(f"{layer}: image is {img.shape[1]}x{img.shape[0]}, LQ is {self.K.width}x{self.K.height}")
        kw = {"params": codec.PNG_LEVEL1, "where": layer, "error": AlignedFormatError}
        if layer in _DEPTH_UNITS:
            unit = self.meta["depth_unit_m"] if _DEPTH_UNITS[layer] is None else _DEPTH_UNITS[layer]
            data = codec.encode_depth_png(img, unit_m=unit, **kw)
        elif layer == "roi":
            data = codec.encode_mask_png(img, **kw)
        else:
            data, _ = codec.encode_color(img, encoding="png", **kw)
        rel = f"{layer}/{i:06d}.png"
        return rel, codec.write_frame_file(self.root / rel, data)

    def add_frame(self, lq_depth: np.ndarray, reference: np.ndarray, *, lq_color=None, roi=None, truth=None,
                  lq_frame: int = -1, hq_frame: int = -1, lq_timestamp_us: int = 0) -> int:
        i = len(self.rows)
        row = {"index": i, "lq_frame": int(lq_frame), "hq_frame": int(hq_frame), "lq_timestamp_us": int(lq_timestamp_us)}
        for layer, img in zip(LAYERS, (lq_depth, lq_color, reference, roi, truth)):
            row[f"{layer}_file"], row[f"{layer}_sha256"] = self._write(layer, i, img)
        self.rows.append(row)
        return i

    def write_table(self, name: str, text: str) -> None:
        """An extra CSV (e.g. ``pairs.csv``) inside the dataset."""
        (self.root / name).write_text(text)

    def close(self) -> Path:
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=list(FRAME_COLUMNS), lineterminator="\n")
        w.writeheader()
        w.writerows(self.rows)
        text = buf.getvalue()
        (self.root / "frames.csv").write_text(text)
        self.meta["frames"] = "frames.csv"
        self.meta["frames_sha256"] = sha256_bytes(text.encode())
        ident = json.dumps({"frames": self.meta["frames_sha256"], "unit": self.meta["depth_unit_m"],
                            "K": self.meta["lq_intrinsics"]}, sort_keys=True)
        self.meta["dataset_checksum"] = sha256_bytes(ident.encode())
        _check_meta(self.meta, self.root / MANIFEST)
        atomic_write_json(self.root / MANIFEST, self.meta)
        try:
            self._stage.__exit__(None, None, None)
        finally:
            self.root = self.final_root
        return self.final_root

    def abort(self) -> None:
        try:
            self._stage.__exit__(AlignedFormatError, AlignedFormatError("aborted"), None)
        except AlignedFormatError:
            pass

    def __enter__(self) -> "AlignedDatasetWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
