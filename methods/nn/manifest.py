"""Training dataset manifests: which aligned datasets a run used, their checksums, and the split.

Format ``depthbench.training`` 1.x (``data_manifests/training.md``, schema
``data_manifests/schemas/training.schema.json``): a JSON file naming aligned datasets by a path
relative to the manifest's folder, each with its ``dataset_checksum`` and a split (``train``,
``validation``, ``test``). The split is by sequence: one aligned dataset is one sequence and all
its frames share a split, so consecutive (nearly identical) frames never straddle train and test.

Opening a manifest opens every dataset it names and checks its checksum; a missing or changed
dataset is a one-line :class:`methods.errors.TrainingManifestError` before any training starts.
The identities recorded in weights (:meth:`TrainingManifest.provenance`) let the benchmark refuse
to score a learned method on its own training or validation sequences.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from align.dataset import AlignedDataset
from align.errors import AlignError
from data_manifests import schema_problem
from depthbench.errors import UnsafePathError
from depthbench.fsutil import atomic_write_json, read_json, safe_join, sha256_file
from methods.errors import TrainingManifestError

FORMAT = "depthbench.training"
FORMAT_VERSION = "1.0"
SPLITS = ("train", "validation", "test")


def source_id(ds: AlignedDataset) -> str:
    """Identity of the recording an aligned dataset came from: the sha256 of its LQ stream's frames
    table in the source session (the dataset checksum when the dataset does not record it).

    Re-aligning a session changes the dataset checksum but not this, so leakage checks use both.
    """
    src = ds.meta.get("source_session") or {}
    sums = src.get("frames_sha256") or {}
    lq = ds.meta.get("lq_sensor")
    value = sums.get(f"{lq}/frames.csv") if lq else None
    return str(value) if value else ds.checksum


@dataclass
class ManifestEntry:
    """One dataset of a manifest, opened."""

    name: str
    split: str
    dataset: AlignedDataset
    info: dict = field(default_factory=dict)

    @property
    def checksum(self) -> str:
        return self.dataset.checksum


@dataclass
class TrainingManifest:
    """An opened, checked training manifest."""

    path: Path
    name: str
    entries: list[ManifestEntry]
    sha256: str
    meta: dict

    def split(self, which: str) -> list[AlignedDataset]:
        """The datasets of one split, in manifest order."""
        if which not in SPLITS:
            raise TrainingManifestError(f"{self.path}: unknown split {which!r} (splits: {', '.join(SPLITS)})")
        return [e.dataset for e in self.entries if e.split == which]

    def provenance(self, splits: tuple[str, ...] = ("train", "validation")) -> dict:
        """What weights record about their data: manifest name and hash, and the identities of
        every dataset in ``splits`` (checksums and source recordings) that the model saw."""
        seen = [e for e in self.entries if e.split in splits]
        return {"manifest": self.name, "manifest_path": str(self.path), "manifest_sha256": self.sha256,
                "splits": list(splits),
                "datasets": [{"name": e.name, "split": e.split, "checksum": e.checksum,
                              "source": source_id(e.dataset)} for e in seen]}


def read_manifest(path: str | os.PathLike) -> TrainingManifest:
    """Open and check a training manifest (every dataset present, checksums equal)."""
    path = Path(path)
    meta = read_json(path, error=TrainingManifestError, missing=" (no such training manifest)")
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise TrainingManifestError(f"{path}: 'format' must be {FORMAT!r} (not a training manifest)")
    problem = schema_problem("training", meta)
    if problem:
        raise TrainingManifestError(f"{path}: {problem}")
    entries: list[ManifestEntry] = []
    names: set[str] = set()
    for item in meta["datasets"]:
        if item["name"] in names:
            raise TrainingManifestError(f"{path}: dataset {item['name']!r} named twice")
        names.add(item["name"])
        try:
            root = safe_join(path.parent, item["path"], source=path)
        except UnsafePathError as exc:
            raise TrainingManifestError(str(exc)) from None
        if not (root / "aligned.json").is_file():
            raise TrainingManifestError(f"{path}: dataset {item['name']!r}: {root} is missing (no aligned.json)")
        try:
            ds = AlignedDataset(root)
        except AlignError as exc:
            raise TrainingManifestError(f"{path}: dataset {item['name']!r}: {exc}") from None
        if ds.checksum != item["checksum"]:
            raise TrainingManifestError(f"{path}: dataset {item['name']!r} at {root} has changed (checksum "
                                        f"{ds.checksum[:12]}..., manifest says {item['checksum'][:12]}...)")
        entries.append(ManifestEntry(item["name"], item["split"], ds, dict(item)))
    return TrainingManifest(path, meta["name"], entries, sha256_file(path), meta)


def manifest_entry(ds: AlignedDataset, *, root: Path, split: str, **extra) -> dict:
    """The manifest record of dataset ``ds`` (which must lie inside ``root``, the manifest's folder)."""
    if split not in SPLITS:
        raise TrainingManifestError(f"unknown split {split!r} (splits: {', '.join(SPLITS)})")
    try:
        rel = Path(os.path.relpath(ds.root.resolve(), root.resolve()))
    except ValueError:
        rel = Path("..")
    if rel.parts and rel.parts[0] == "..":
        raise TrainingManifestError(f"{ds.root}: a dataset must lie inside the manifest's folder {root}")
    return {"name": ds.name, "path": rel.as_posix(), "checksum": ds.checksum, "split": split,
            "sequence": ds.sequence, "source": source_id(ds), "frames": len(ds), **extra}


def write_manifest(path: str | os.PathLike, *, name: str, entries: list[dict], created: dict | None = None,
                   description: str | None = None) -> Path:
    """Write a manifest atomically (checked against the schema first)."""
    path = Path(path)
    meta = {"format": FORMAT, "format_version": FORMAT_VERSION, "name": name}
    if description:
        meta["description"] = description
    if created:
        meta["created"] = created
    meta["datasets"] = entries
    problem = schema_problem("training", meta)
    if problem:
        raise TrainingManifestError(f"{path}: {problem}")
    atomic_write_json(path, meta)
    return path
