"""Test-only methods for the interface seams (importable by worker processes).

:class:`TemporalMean` is a sequence method with a weights file: an exponential running mean over
the frames of a sequence, ``y_t = a * y_(t-1) + (1 - a) * x_t`` where both exist (``x_t`` where the
state has no depth, NaN where the frame has none), plus ``offset_m``; ``a`` and ``offset_m`` come
from its weights (``.npz`` or ``.safetensors``). :func:`temporal_mean_reference` is the same
model as a direct loop over a list of frames, written independently of the runner.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from methods.base import Denoiser
from methods.errors import MethodError


def write_weights(path: Path, *, alpha: float, offset_m: float = 0.0) -> Path:
    """A tiny weights file of :class:`TemporalMean`."""
    arrays = {"alpha": np.array(alpha, np.float32), "offset_m": np.array(offset_m, np.float32)}
    if path.suffix == ".safetensors":
        from safetensors.numpy import save_file

        save_file(arrays, str(path))
    else:
        with open(path, "wb") as fh:
            np.savez(fh, **arrays)
    return path


class TemporalMean(Denoiser):
    """Running temporal mean; the whole sequence is one chunk."""

    name = "test_temporal_mean"
    version = "1"
    learned = True
    sequential = True
    weights_param = "weights"
    defaults = {"weights": None}

    def prepare(self):
        w = self.load_weights()
        self.runtime["alpha"] = float(w["alpha"])
        self.runtime["offset_m"] = np.float32(w["offset_m"])
        self.runtime["prepared_in"] = id(self)

    def start_sequence(self):
        return None

    def _step(self, frame, state):
        a = self.runtime["alpha"]
        x = frame.depth
        if state is None:
            y = x.copy()
        else:
            y = np.where(np.isfinite(state) & np.isfinite(x), a * state + (1 - a) * x, x).astype(np.float32)
        return y + self.runtime["offset_m"], y


class ChunkedTemporalMean(TemporalMean):
    """The same model, in chunks of 2 frames with 1 warm-up frame."""

    name = "test_temporal_mean_chunked"
    chunk_frames = 2
    warmup_frames = 1


class BatchedScale(Denoiser):
    """A frame method with batched inference: multiplies depth by ``factor``; records batch sizes."""

    name = "test_batched_scale"
    batch_size = 2
    defaults = {"factor": 1.01}
    calls: list[int] = []

    def _denoise_batch(self, frames):
        type(self).calls.append(len(frames))
        stack = np.stack([f.depth for f in frames])
        return list(stack * np.float32(self.params["factor"]))


class RejectFrame(Denoiser):
    """A frame method that refuses frames whose mean depth is beyond ``above_m`` metres (MethodError)."""

    name = "test_reject_frame"
    defaults = {"above_m": 1.5}

    def _denoise(self, depth, color, camera):
        if np.nanmean(depth) > self.params["above_m"]:
            raise MethodError(f"{self.name}: mean depth {np.nanmean(depth):.3f} m is too far")
        return depth.copy()


def temporal_mean_reference(frames: list[np.ndarray], *, alpha: float, offset_m: float,
                            chunk: int | None = None, warmup: int = 0) -> list[np.ndarray]:
    """The running mean as a direct loop, restarted every ``chunk`` frames after ``warmup`` earlier frames."""
    n = len(frames)
    chunk = chunk or n
    out: list[np.ndarray] = []
    for start in range(0, n, chunk):
        y = None
        for t in range(max(0, start - warmup), min(start + chunk, n)):
            x = frames[t].astype(np.float64)
            if not np.isfinite(x).any():
                if t >= start:
                    out.append(np.full(x.shape, np.nan, np.float32))
                continue
            if y is None:
                y = x.copy()
            else:
                both = np.isfinite(y) & np.isfinite(x)
                y = np.where(both, alpha * y + (1 - alpha) * x, x)
            if t >= start:
                out.append((y + offset_m).astype(np.float32))
    return out


class RefuseDataset(Denoiser):
    """A method that refuses to be scored on the dataset named ``name`` (as a learned method refuses its training data)."""

    name = "test_refuse_dataset"
    defaults = {"name": "S1"}

    def check_dataset(self, dataset):
        if dataset.name == self.params["name"]:
            raise MethodError(f"{self.name}: {dataset.root} is in its training split")

    def _denoise(self, depth, color, camera):
        return depth.copy()
