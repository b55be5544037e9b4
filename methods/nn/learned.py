"""A base class for frame-by-frame learned methods: weights checked when configured, the network
rebuilt from the training config stored in the file, the leakage guard and provenance of
:mod:`methods.nn.weights`.

A subclass sets ``name``, ``trained_as`` (the trainer's method names whose weights it accepts),
``schema`` (the training config dataclass) and implements :meth:`build` (config -> network) and
:meth:`_run` (one frame through the network). Anything wrong with the weights file (missing,
truncated, corrupt, a pickle, another method's, a config this code no longer accepts, mis-shaped
tensors) is one :class:`methods.errors.CheckpointError` line naming the file, raised when the method
is configured, before any frame is read.
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from methods.base import Denoiser, check_flag, resolve_device
from methods.errors import CheckpointError

log = logging.getLogger(__name__)


def deviations(config: Any, default: Any, keys: tuple[str, ...]) -> list[str]:
    """``"section.key = value"`` for each dotted key of ``keys`` whose value in ``config`` differs from
    ``default`` (two instances of one config dataclass)."""
    def get(obj: Any, key: str) -> Any:
        for part in key.split("."):
            obj = getattr(obj, part)
        return obj

    return [f"{k} = {get(config, k)!r}" for k in keys if get(config, k) != get(default, k)]


class LearnedDenoiser(Denoiser):
    """Weights from ``depthbench methods train``; holes of the input stay holes unless ``fill_holes``."""

    learned = True
    weights_param = "weights"
    device = "auto"
    trained_as: ClassVar[tuple[str, ...]] = ()
    schema: ClassVar[type | None] = None
    # dotted config keys of options that are not in the paper (their default is the paper's method);
    # provenance names those the weights were trained with at a non-default value
    not_in_paper: ClassVar[tuple[str, ...]] = ()
    defaults = {"weights": None, "fill_holes": False, "allow_train_frames": False}
    param_help = {
        "weights": "weights file from 'depthbench methods train' (RUN/<method>.safetensors)",
        "fill_holes": "true: output depth also where the LQ sensor has none (default false: keep its holes)",
        "allow_train_frames": "true: score even on the weights' own training/validation datasets (marked loudly)",
    }

    def check_params(self, params: dict[str, Any]) -> None:
        from methods.nn.config import from_dict
        from methods.nn.weights import weights_meta

        check_flag(params["fill_holes"], "fill_holes", method=self.name)
        check_flag(params["allow_train_frames"], "allow_train_frames", method=self.name)
        self.meta = weights_meta(params["weights"], methods=self.trained_as or (self.name,))
        try:
            self.config = from_dict(self.schema, self.meta.get("config") or {}, where=str(params["weights"]))
        except Exception as exc:  # noqa: BLE001 (any config problem is one line naming the file)
            raise CheckpointError(f"{params['weights']}: its training config does not fit this code "
                                  f"({str(exc).splitlines()[0]})") from None
        self._load_net(Path(params["weights"]).read_bytes())  # truncated or mis-shaped tensors fail here
        self.leaked: list[str] = []

    def _load_net(self, data: bytes):
        """The network with the file's tensors loaded strictly (CPU)."""
        from methods.nn.checkpoint import decode_tensors, load_state

        f = decode_tensors(data, where=self.params["weights"], kind="weights")
        net = self.build(self.config)
        load_state(net, f.prefixed("net/"), where=self.params["weights"])
        return net

    def check_dataset(self, dataset: Any) -> None:
        from methods.nn.weights import TrainingDataError, leak

        why = leak(self.meta, dataset)
        if why is None:
            return
        if not self.params["allow_train_frames"]:
            raise TrainingDataError(f"{self.name}: {why}; scoring it would flatter the model "
                                    "(allow_train_frames=true to score it anyway, marked)")
        self.leaked.append(dataset.name)
        log.warning("%s: SCORED ON ITS OWN TRAINING DATA: %s", self.name, why)

    def provenance(self) -> dict[str, Any]:
        from methods.nn.weights import provenance

        out = provenance(self.meta)
        options = deviations(self.config, self.schema(), self.not_in_paper) if self.not_in_paper else []
        if options:
            out["not_in_paper"] = options
        if self.leaked:
            out["WARNING"] = f"scored on its own training/validation data: {', '.join(sorted(set(self.leaked)))}"
        return out

    def build(self, config: Any):
        """The network of ``config`` (untrained); its tensors are loaded from ``net/...``."""
        raise NotImplementedError

    def prepare(self) -> None:
        import torch

        net = self._load_net(self.weights_bytes())
        dev = torch.device(resolve_device(self.device))
        self.runtime.update(net=net.to(dev).eval(), device=dev)

    def _run(self, depth, color) -> "np.ndarray":
        """One frame: depth ``(1, 1, H, W)`` tensor metres (NaN holes), colour ``(1, 3, H, W)`` in [0, 1] or None."""
        raise NotImplementedError

    def _denoise(self, depth, color, camera):
        import torch

        if not self.runtime:
            self.prepare()
        dev = self.runtime["device"]
        d = torch.from_numpy(depth)[None, None].to(dev)
        c = None
        if self.uses_color and color is not None:
            scale = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(color.dtype, 1.0)
            rgb = color if color.ndim == 3 else np.repeat(color[..., None], 3, axis=2)
            c = torch.from_numpy(np.ascontiguousarray(rgb.transpose(2, 0, 1), dtype=np.float32) / scale)[None].to(dev)
        with torch.inference_mode():
            out = self._run(d, c)[0, 0].float().cpu().numpy()
        if not self.params["fill_holes"]:
            out = np.where(np.isfinite(depth), out, np.nan)
        return out.astype(np.float32)
