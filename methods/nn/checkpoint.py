"""Weights and checkpoints on disk: safetensors files, tensors only, written atomically.

A file holds named tensors and a flat ``str -> str`` metadata map (the safetensors header), and
nothing else: loading never unpickles Python objects, so a weights file from elsewhere cannot run
code. Every file written here carries ``format = depthbench.weights`` and a ``kind`` in its
metadata (``weights``: what inference loads; ``checkpoint``: weights plus optimizer state for
resuming; ``predictions``: arrays a run computed, e.g. out-of-fold predictions); other JSON values in the metadata (config, training provenance) are JSON strings.

A missing, truncated, corrupt or foreign file (a ``torch.save`` pickle, another program's
safetensors) is a one-line :class:`methods.errors.CheckpointError` naming the file.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import torch

from depthbench.fsutil import atomic_output, sha256_bytes, sha256_file
from methods.errors import CheckpointError

FORMAT = "depthbench.weights"
FORMAT_VERSION = "1"
KINDS = ("weights", "checkpoint", "predictions")


@dataclass
class TensorFile:
    """What a weights/checkpoint file holds: tensors by name, and decoded metadata.

    ``meta`` values are JSON-decoded (dicts, numbers, strings); ``sha256`` is the file's hash.
    """

    tensors: dict[str, torch.Tensor]
    meta: dict = field(default_factory=dict)
    path: Path | None = None
    sha256: str = ""

    def prefixed(self, prefix: str) -> dict[str, torch.Tensor]:
        """Tensors whose name starts with ``prefix``, with it removed (e.g. one sub-network's)."""
        return {k[len(prefix):]: v for k, v in self.tensors.items() if k.startswith(prefix)}


def save_tensors(path: str | os.PathLike, tensors: dict[str, torch.Tensor], *, kind: str, meta: dict | None = None) -> str:
    """Write ``tensors`` (contiguous CPU copies) and ``meta`` to ``path`` atomically; returns its sha256."""
    from safetensors.torch import save_file

    if kind not in KINDS:
        raise CheckpointError(f"{path}: kind must be one of {', '.join(KINDS)}, got {kind!r}")
    header = {"format": FORMAT, "format_version": FORMAT_VERSION, "kind": kind}
    for k, v in (meta or {}).items():
        header[k] = json.dumps(v, sort_keys=True)
    cpu = {k: v.detach().to("cpu").contiguous().clone() for k, v in tensors.items()}
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(path) as tmp:
        save_file(cpu, str(tmp), metadata=header)
    return sha256_file(path)


def read_header(data: bytes, *, where: str | os.PathLike) -> dict:
    """The string metadata of a safetensors file's header (from its bytes), without reading tensors."""
    if len(data) < 8:
        raise CheckpointError(f"{where}: not a readable safetensors weights file (too short); "
                              "weights are loaded as tensors only, never unpickled")
    n = int.from_bytes(data[:8], "little")
    try:
        if n > len(data) - 8:
            raise ValueError("header length beyond the end of the file")
        header = json.loads(data[8:8 + n])
        if not isinstance(header, dict):
            raise ValueError("header is not a JSON object")
    except (ValueError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{where}: not a readable safetensors weights file ({exc}); "
                              "weights are loaded as tensors only, never unpickled") from None
    meta = header.get("__metadata__") or {}
    return meta if isinstance(meta, dict) else {}


def decode_meta(header: dict, *, where: str | os.PathLike, kind: str | None = None) -> dict:
    """Check a header's format fields (and ``kind``) and JSON-decode the other metadata values."""
    if header.get("format") != FORMAT:
        raise CheckpointError(f"{where}: not a depthbench weights file (metadata format {header.get('format')!r}, "
                              f"expected {FORMAT!r})")
    if header.get("format_version") != FORMAT_VERSION:
        raise CheckpointError(f"{where}: weights format version {header.get('format_version')!r} is not "
                              f"{FORMAT_VERSION!r}")
    if kind is not None and header.get("kind") != kind:
        raise CheckpointError(f"{where}: holds {header.get('kind')!r}, expected {kind!r}")
    meta = {}
    for k, v in header.items():
        if k in ("format", "format_version", "kind"):
            meta[k] = v
            continue
        try:
            meta[k] = json.loads(v)
        except (json.JSONDecodeError, TypeError):
            raise CheckpointError(f"{where}: metadata field {k!r} is not JSON") from None
    return meta


def decode_tensors(data: bytes, *, where: str | os.PathLike, kind: str | None = None) -> TensorFile:
    """A :class:`TensorFile` from the bytes of a file written by :func:`save_tensors` (never unpickles)."""
    from safetensors import SafetensorError
    from safetensors.torch import load

    meta = decode_meta(read_header(data, where=where), where=where, kind=kind)
    try:
        tensors = load(data)
    except (SafetensorError, ValueError, RuntimeError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise CheckpointError(f"{where}: not a readable safetensors weights file ({reason}); "
                              "weights are loaded as tensors only, never unpickled") from None
    return TensorFile(tensors, meta, Path(where), sha256_bytes(data))


def load_tensors(path: str | os.PathLike, *, kind: str | None = None) -> TensorFile:
    """Read a file written by :func:`save_tensors`; ``kind`` (if given) must match.

    Raises :class:`CheckpointError` (one line) for anything else.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise CheckpointError(f"{path}: no such weights file") from None
    except OSError as exc:
        raise CheckpointError(f"{path}: cannot read ({exc.strerror or exc})") from None
    return decode_tensors(data, where=path, kind=kind)


def load_state(module: torch.nn.Module, tensors: dict[str, torch.Tensor], *, where: str | os.PathLike) -> None:
    """Load ``tensors`` into ``module`` strictly: missing, unexpected or mis-shaped tensors are errors."""
    own = module.state_dict()
    missing = sorted(set(own) - set(tensors))
    extra = sorted(set(tensors) - set(own))
    if missing or extra:
        what = f"missing {missing[0]!r}" if missing else f"unexpected {extra[0]!r}"
        raise CheckpointError(f"{where}: weights do not fit the network ({what}; "
                              f"{len(missing)} missing, {len(extra)} unexpected); was it trained with another config?")
    for k, v in tensors.items():
        if own[k].shape != v.shape:
            raise CheckpointError(f"{where}: tensor {k!r} has shape {tuple(v.shape)}, the network expects "
                                  f"{tuple(own[k].shape)}; was it trained with another config?")
    module.load_state_dict(tensors, strict=True)


def optimizer_tensors(optimizer: torch.optim.Optimizer) -> dict[str, torch.Tensor]:
    """An optimizer's per-parameter state as flat named tensors (``optim/<param>/<name>``).

    Hyper-parameters (learning rate, betas) come from the config, not from the file.
    """
    out = {}
    state = optimizer.state_dict()["state"]
    for idx, entries in state.items():
        for name, value in entries.items():
            t = value if torch.is_tensor(value) else torch.tensor(value)
            out[f"optim/{idx}/{name}"] = t
    return out


def load_optimizer_tensors(optimizer: torch.optim.Optimizer, tensors: dict[str, torch.Tensor], *,
                           where: str | os.PathLike) -> None:
    """Inverse of :func:`optimizer_tensors` for an optimizer built the same way."""
    sd = optimizer.state_dict()
    state: dict[int, dict] = {}
    for key, value in tensors.items():
        if not key.startswith("optim/"):
            continue
        try:
            _, idx, name = key.split("/", 2)
            state.setdefault(int(idx), {})[name] = value
        except ValueError:
            raise CheckpointError(f"{where}: bad optimizer tensor name {key!r}") from None
    n_params = sum(len(g["params"]) for g in sd["param_groups"])
    if any(i >= n_params for i in state):
        raise CheckpointError(f"{where}: optimizer state for {max(state) + 1} parameters, the network has {n_params}")
    sd["state"] = state
    try:
        optimizer.load_state_dict(sd)
    except (ValueError, RuntimeError, KeyError) as exc:
        raise CheckpointError(f"{where}: optimizer state does not fit ({exc})") from None
