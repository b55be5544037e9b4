"""Loading a trained network for inference: a weights file from ``depthbench methods train`` -> module.

A weights file (:mod:`methods.nn.checkpoint`, tensors only) records the method it was trained for
and the resolved training config; :func:`load_network` checks both, rebuilds the config dataclass
and the network from it, and loads the tensors strictly. Anything wrong (not a weights file, a
corrupt or foreign file, weights of another method, a config the code no longer accepts,
mis-shaped tensors) is one :class:`methods.errors.CheckpointError` line naming the file.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import torch

from methods.errors import CheckpointError
from methods.nn.checkpoint import TensorFile, load_state, load_tensors
from methods.nn.config import from_dict


@dataclass
class LoadedNetwork:
    """The network (eval mode, CPU), its config and the file's metadata."""

    net: torch.nn.Module
    config: Any
    meta: dict


def read_weights(path: str | Path, *, method: str | tuple[str, ...]) -> TensorFile:
    """The weights file, checked to hold weights trained for ``method`` (a name or several)."""
    tf = load_tensors(path, kind="weights")
    names = (method,) if isinstance(method, str) else method
    if tf.meta.get("method") not in names:
        raise CheckpointError(f"{path}: weights of {tf.meta.get('method')!r}, not of {' or '.join(map(repr, names))}")
    return tf


def load_network(path: str | Path, *, method: str, schema: type, build: Callable[[Any], torch.nn.Module],
                 prefix: str = "net/", sha256: str | None = None) -> LoadedNetwork:
    """Rebuild ``build(config)`` from the file's config (``schema``) and load its ``prefix`` tensors.

    ``sha256``: the content hash the caller's method key names; a file changed since is an error.
    """
    tf = read_weights(path, method=method)
    if sha256 is not None and tf.sha256 != sha256:
        raise CheckpointError(f"{path}: changed since the method was configured (sha256 differs)")
    try:
        cfg = from_dict(schema, tf.meta.get("config") or {}, where=str(path))
    except Exception as exc:  # config errors of any kind name the file
        raise CheckpointError(f"{path}: its training config does not fit this code ({str(exc).splitlines()[0]})") from None
    net = build(cfg)
    load_state(net, tf.prefixed(prefix), where=path)
    net.eval()
    return LoadedNetwork(net, cfg, tf.meta)
