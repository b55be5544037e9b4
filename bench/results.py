"""The results folder: the Parquet table, its manifest, the per-task cache and the depth previews.

Layout (documented in ``data_manifests/results.md``)::

    RESULTS/
      results.json                 manifest (schemas/results.schema.json): schema version, metric
                                   parameters, datasets, methods, run history, table checksum
      results.parquet              one row per (method, dataset, frame, reference, metric[, depth bin])
      cache/<ds>/<mk>/<frame>.parquet   the rows of one (method key, dataset checksum, frame): reused
      previews/<ds>/inputs.npz     middle frame of each dataset: LQ, reference, truth, ROI, colour, intrinsics
      previews/<ds>/<mk>.npz       that frame denoised by each method
      leaderboard.md, leaderboard.html, figures/   the report (derived; rebuilt from the table)

``<ds>`` is the first 16 hex digits of the dataset checksum, ``<mk>`` those of sha256(method key).
Everything is written through a temporary name and renamed; ``.npz`` files hold no pickles.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from bench.errors import BenchError, ResultsFormatError, SchemaVersionError  # noqa: F401 (re-exported)
from data_manifests import schema_problem
from depthbench.fsutil import atomic_output, atomic_write_json, read_json, sha256_file

FORMAT = "depthbench.results"
SCHEMA_VERSION = 3   # 2: "truth" scored on the reference's pixels, "truth_noref" the rest of the ROI;
#                      3: "hq_interior" and "truth_interior", away from the reference's depth edges
MANIFEST = "results.json"
TABLE = "results.parquet"
CACHE = "cache"
PREVIEWS = "previews"

#: Columns of the results table, in order, with their Arrow types.
SCHEMA = pa.schema([
    ("schema_version", pa.int32()),
    ("method", pa.string()),            # registry name, e.g. "bf"
    ("method_version", pa.string()),    # Denoiser.version
    ("method_key", pa.string()),        # name@version(params): the cache identity
    ("dataset", pa.string()),           # aligned dataset name
    ("dataset_checksum", pa.string()),  # aligned.json dataset_checksum
    ("sequence", pa.string()),          # sequence name for per-sequence tables
    ("frame", pa.int64()),              # frame index in the aligned dataset
    ("reference", pa.string()),         # "hq" (warped HQ depth), "truth" (simulated noise-free depth on the
                                        # hq reference's pixels), "truth_noref" (on the ROI pixels without one),
                                        # "hq_interior" / "truth_interior" (hq's pixels away from its depth edges)
    ("metric", pa.string()),            # see bench.metrics.UNITS
    ("unit", pa.string()),              # mm, mm^2, ratio, count, deg
    ("bin_lo_m", pa.float64()),         # reference-depth bin [lo, hi) in metres; NaN: the whole frame
    ("bin_hi_m", pa.float64()),
    ("value", pa.float64()),            # NaN where undefined (e.g. no scored pixel)
])
COLUMNS = tuple(SCHEMA.names)
_META = {b"depthbench.format": FORMAT.encode(), b"depthbench.schema_version": str(SCHEMA_VERSION).encode()}


def short(text: str) -> str:
    """First 16 hex digits of sha256(text): folder names in the cache and previews."""
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def cache_part(root: Path, method_key: str, dataset_checksum: str, frame: int) -> Path:
    return root / CACHE / dataset_checksum[:16] / short(method_key) / f"{frame:06d}.parquet"


def preview_path(root: Path, dataset_checksum: str, method_key: str | None = None) -> Path:
    return root / PREVIEWS / dataset_checksum[:16] / ("inputs.npz" if method_key is None else f"{short(method_key)}.npz")


# ----------------------------------------------------------------------------------- tables
def to_arrow(df: pd.DataFrame) -> pa.Table:
    """A results DataFrame as an Arrow table with :data:`SCHEMA` and the format metadata."""
    missing = [c for c in COLUMNS if c not in df.columns]
    if missing:
        raise ResultsFormatError(f"results rows lack columns {missing}")
    table = pa.Table.from_pandas(df[list(COLUMNS)], schema=SCHEMA, preserve_index=False)
    return table.replace_schema_metadata(_META)


def write_table(df: pd.DataFrame, path: Path) -> str:
    """Write rows atomically as Parquet (zstd); returns the file's sha256."""
    table = to_arrow(df)
    with atomic_output(path) as tmp:
        pq.write_table(table, tmp, compression="zstd")
        digest = hashlib.sha256(tmp.read_bytes()).hexdigest()
    return digest


def read_table(path: Path) -> pd.DataFrame:
    """Read a results table (or cache part); checks format and schema version."""
    return _rows(open_table(path), Path(path))


def open_table(path: Path) -> pq.ParquetFile:
    """Open a results table (or cache part) and check its format, schema version and columns
    (from the file's footer; the rows are not read yet)."""
    path = Path(path)
    try:
        pf = pq.ParquetFile(path)
    except FileNotFoundError:
        raise ResultsFormatError(f"{path}: missing") from None
    except (pa.ArrowInvalid, OSError) as exc:
        raise ResultsFormatError(f"{path}: not a readable Parquet file ({str(exc).splitlines()[0]})") from None
    meta = pf.schema_arrow.metadata or {}
    version = meta.get(b"depthbench.schema_version")
    if meta.get(b"depthbench.format") != FORMAT.encode() or version is None:
        raise ResultsFormatError(f"{path}: not a depthbench results table (no {FORMAT} metadata)")
    if version != str(SCHEMA_VERSION).encode():
        raise SchemaVersionError(f"{path}: results schema version {version.decode()}, this depthbench reads version "
                                 f"{SCHEMA_VERSION} (recompute the results with this version)")
    names = tuple(pf.schema_arrow.names)
    if names != COLUMNS:
        raise ResultsFormatError(f"{path}: columns {list(names)} differ from schema version {SCHEMA_VERSION}'s {list(COLUMNS)}")
    return pf


def _rows(pf: pq.ParquetFile, path: Path) -> pd.DataFrame:
    try:
        df = pf.read().to_pandas()
    except (pa.ArrowException, OSError) as exc:
        raise ResultsFormatError(f"{path}: damaged Parquet data ({str(exc).splitlines()[0]})") from None
    bad = df["schema_version"] != SCHEMA_VERSION
    if bad.any():
        raise SchemaVersionError(f"{path}: rows with schema_version {int(df['schema_version'][bad].iloc[0])}, this "
                                 f"depthbench reads version {SCHEMA_VERSION}")
    return df


def read_parts(paths: list[Path]) -> pd.DataFrame:
    """Concatenate cache parts (each checked)."""
    if not paths:
        return empty_frame()
    return pd.concat([read_table(p) for p in paths], ignore_index=True)


def empty_frame() -> pd.DataFrame:
    return SCHEMA.empty_table().to_pandas()


def sort_rows(df: pd.DataFrame) -> pd.DataFrame:
    """The table's canonical row order (so equal results give byte-identical files)."""
    return df.sort_values(["dataset", "method_key", "frame", "reference", "metric", "bin_lo_m"],
                          na_position="first", kind="mergesort").reset_index(drop=True)


# ----------------------------------------------------------------------------------- manifest
def read_manifest(root: Path) -> dict:
    """``results.json`` of a results folder, checked against its schema and version."""
    path = Path(root) / MANIFEST
    meta = read_json(path, error=ResultsFormatError, missing=" (not a depthbench results folder)")
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ResultsFormatError(f"{path}: 'format' must be {FORMAT!r} (not a depthbench results folder)")
    if meta.get("schema_version") != SCHEMA_VERSION:
        raise SchemaVersionError(f"{path}: results schema version {meta.get('schema_version')!r}, this depthbench "
                                 f"reads version {SCHEMA_VERSION} (recompute the results with this version)")
    problem = schema_problem("results", meta)
    if problem:
        raise ResultsFormatError(f"{path}: {problem}")
    return meta


def write_manifest(root: Path, meta: dict) -> None:
    problem = schema_problem("results", meta)
    if problem:   # a bug, not user input
        raise ResultsFormatError(f"{Path(root) / MANIFEST}: refusing to write an invalid manifest: {problem}")
    atomic_write_json(Path(root) / MANIFEST, meta)


def load_results(path: str | os.PathLike) -> pd.DataFrame:
    """The results table of a results folder (or a ``results.parquet`` path), checked.

    When a ``results.json`` lies beside the table it must be valid (JSON, this schema version) and
    the table must have the sha256 and row count it records: a table changed or damaged after
    its run is refused before any of it is read."""
    path = Path(path)
    if path.is_dir():
        if not (path / TABLE).exists():
            if (path / MANIFEST).exists():
                read_manifest(path)    # reports a schema mismatch first
            raise ResultsFormatError(f"{path}: no {TABLE} (not a results folder, or no run finished into it)")
        path = path / TABLE
    elif not path.exists():
        raise ResultsFormatError(f"{path}: no such results folder or table")
    pf = open_table(path)              # the file's own format and schema version first
    recorded = _recorded_table(path)   # then results.json and the sha256 it records, before any row is read
    df = _rows(pf, path)
    if recorded is not None and recorded.get("rows") is not None and int(recorded["rows"]) != len(df):
        raise ResultsFormatError(f"{path}: {len(df)} rows, {MANIFEST} records {recorded['rows']}")
    return df


def _recorded_table(path: Path) -> dict | None:
    """The manifest's ``table`` entry for the table file ``path`` (checked against its sha256), or
    ``None`` when no manifest lies beside it or the manifest records no table of that name."""
    if not (path.parent / MANIFEST).exists():
        return None
    recorded = read_manifest(path.parent).get("table")
    if not recorded or recorded.get("file") != path.name:
        return None
    digest = sha256_file(path)
    if digest != recorded["sha256"]:
        raise ResultsFormatError(f"{path}: sha256 {digest[:16]}... differs from {recorded['sha256'][:16]}... recorded "
                                 f"in {MANIFEST} (the table was changed or damaged after its run)")
    return recorded


# ----------------------------------------------------------------------------------- previews
def save_npz(path: Path, **arrays) -> None:
    """Compressed ``.npz`` without pickles, written atomically."""
    path.parent.mkdir(parents=True, exist_ok=True)
    clean = {k: np.asarray(v) for k, v in arrays.items() if v is not None}
    for k, v in clean.items():
        if v.dtype == object:
            raise ResultsFormatError(f"{path}: array {k!r} would need a pickle")
    with atomic_output(path) as tmp:
        with open(tmp, "wb") as f:
            np.savez_compressed(f, **clean)


def load_npz(path: Path) -> dict[str, np.ndarray] | None:
    """A preview ``.npz`` (no pickles allowed), or None when absent."""
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except FileNotFoundError:
        return None
    except (ValueError, OSError) as exc:
        raise ResultsFormatError(f"{path}: unreadable preview ({exc})") from None
