"""What learned Denoisers share: reading their weights file's metadata, naming its provenance, and
refusing to be scored on their own training data.

Weights files (:mod:`methods.nn.checkpoint`) record the training manifest and every train and
validation dataset by checksum and by source recording (:func:`methods.nn.manifest.source_id`).
:func:`leak` finds an aligned dataset among them: a leaderboard that scored a model on frames it
was trained or validated on would flatter it (the classic way learned leaderboards lie).
"""
from __future__ import annotations

from pathlib import Path

from methods.errors import CheckpointError, MethodError
from methods.nn.checkpoint import decode_meta, read_header


class TrainingDataError(MethodError):
    """A learned method asked to score a dataset from its own training or validation split."""


def weights_meta(path: str | Path, *, methods: tuple[str, ...]) -> dict:
    """The decoded metadata of weights file ``path``, which must be ``kind = weights`` of one of ``methods``.

    Reads the header only (cheap: done when a method is configured, so a bad file fails early).
    """
    path = Path(path)
    try:
        with open(path, "rb") as f:
            head = f.read(8)
            n = int.from_bytes(head, "little") if len(head) == 8 else 0
            data = head + f.read(min(n, 64 << 20))
    except OSError as exc:
        raise CheckpointError(f"{path}: cannot read ({exc.strerror or exc})") from None
    meta = decode_meta(read_header(data, where=path), where=path, kind="weights")
    if meta.get("method") not in methods:
        raise CheckpointError(f"{path}: weights of {meta.get('method')!r}, expected {' or '.join(methods)}")
    return meta


def provenance(meta: dict, *, config_sections: tuple[str, ...] = ()) -> dict:
    """What a leaderboard names for a learned column: manifest, config file, revision, training datasets."""
    training = meta.get("training") or {}
    return {"trained_method": meta.get("method"), "train_manifest": training.get("manifest"),
            "train_manifest_sha256": training.get("manifest_sha256"), "config_file": meta.get("config_file"),
            "git_revision": meta.get("git_revision"),
            "trained_on": [f"{d['name']} ({d['split']})" for d in training.get("datasets", [])]}


def leak(meta: dict, dataset) -> str | None:
    """Why ``dataset`` (an ``AlignedDataset``) must not be scored with these weights, or None.

    A match by dataset checksum, or by source recording (the same frames aligned again).
    """
    from methods.nn.manifest import source_id

    source = source_id(dataset)
    training = meta.get("training") or {}
    for d in training.get("datasets", []):
        how = "checksum" if d.get("checksum") == dataset.checksum else (
            "source recording" if d.get("source") == source else None)
        if how:
            return (f"{dataset.root}: dataset {dataset.name!r} is in the {d.get('split')} split of the weights' "
                    f"training manifest {training.get('manifest')!r} (same {how} as {d.get('name')!r})")
    return None
