"""The training loop every learned method uses: seeded, resumable, multi-process, with curves.

:func:`fit` trains one network described by a :class:`FitJob` (model, loss, data, optimisation)
and keeps, in the job's folder:

* ``checkpoint.safetensors``: weights, optimizer state and the history so far, rewritten
  atomically after every epoch; a later call with ``resume=True`` continues after its epoch;
* ``history.csv``: per epoch, the training loss (mean over the epoch), the validation loss, the
  seconds taken and the samples per second;
* ``curves.png``: the learning curves.

Sampling: each epoch draws ``samples_per_epoch`` samples (default: every sample once) as a random
permutation fixed by ``(seed, epoch)``, cut into global batches of ``batch_size``; an incomplete
last batch is dropped. In a group of N processes (:mod:`methods.nn.distributed`) each takes
``batch[rank::N]`` of every global batch and DDP averages the gradients: with a per-pixel-mean loss
this is the same step as one process with the whole batch. ``batch_size`` must divide by N.

Validation (every epoch): the loss over every validation sample, unaugmented, summed over the
processes. Determinism: weights are initialised from ``seed`` by the caller (:func:`seeded`), the
sample order and augmentations depend on ``(seed, epoch, sample)`` only, so one seed on CPU gives
the same weights twice.
"""
from __future__ import annotations

import csv
import io
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import torch
from torch import nn
from torch.utils.data import DataLoader, Dataset
from tqdm import tqdm

from depthbench.fsutil import atomic_write_text
from methods.errors import TrainingError
from methods.nn.checkpoint import (load_optimizer_tensors, load_state, load_tensors, optimizer_tensors,
                                   save_tensors)
from methods.nn.config import OptimConfig
from methods.nn.distributed import Dist, wrap

CHECKPOINT = "checkpoint.safetensors"
HISTORY = "history.csv"
CURVES = "curves.png"
HISTORY_COLUMNS = ("epoch", "train_loss", "val_loss", "seconds", "samples_per_s")

#: ``loss(model, batch) -> scalar`` or ``(scalar, {term: scalar})``: the batch's mean loss (see
#: :mod:`methods.nn.losses`); named terms are averaged per epoch into the history (``train_<term>``).
LossFn = Callable[[nn.Module, dict], "torch.Tensor | tuple[torch.Tensor, dict]"]


@dataclass
class FitJob:
    """One network to train.

    Attributes:
        name: label in progress bars and messages (e.g. ``"level1 fold 0"``).
        model: the network, initialised (use :func:`seeded` for reproducible weights).
        loss: the batch's mean loss, see :data:`LossFn`.
        train: training samples (a dataset with ``set_epoch(epoch)``, e.g. :class:`AlignedSamples`).
        validation: validation samples or None.
        optim: epochs, batch size, learning rate, seed.
        folder: where the checkpoint, history and curves go (created by the main process).
        meta: extra metadata stored in the checkpoint (JSON values).
    """

    name: str
    model: nn.Module
    loss: LossFn
    train: Dataset
    validation: Dataset | None
    optim: OptimConfig
    folder: Path
    meta: dict = field(default_factory=dict)
    num_workers: int = 0


@dataclass
class FitResult:
    """The trained model (unwrapped, on the training device) and its history (one dict per epoch)."""

    model: nn.Module
    history: list[dict]
    resumed_from: int = 0

    @property
    def samples_per_s(self) -> float:
        rates = [h["samples_per_s"] for h in self.history if h.get("samples_per_s")]
        return float(np.median(rates)) if rates else float("nan")


def seeded(factory: Callable[[], nn.Module], seed: int) -> nn.Module:
    """Build a network with the global torch RNG seeded by ``seed`` (same seed, same initial weights)."""
    state = torch.random.get_rng_state()
    torch.manual_seed(int(seed))
    try:
        return factory()
    finally:
        torch.random.set_rng_state(state)


def epoch_batches(n: int, *, optim: OptimConfig, epoch: int) -> list[np.ndarray]:
    """The global batches (sample numbers) of ``epoch``: a permutation fixed by (seed, epoch)."""
    want = optim.samples_per_epoch or n
    rng = np.random.default_rng([optim.seed, 7919, epoch])
    order = np.concatenate([rng.permutation(n) for _ in range(math.ceil(want / n))])[:want]
    nb = len(order) // optim.batch_size
    if nb == 0:
        raise TrainingError(f"an epoch of {want} samples holds no full batch of {optim.batch_size}; "
                            "lower optim.batch_size or raise optim.samples_per_epoch")
    return [order[i * optim.batch_size:(i + 1) * optim.batch_size] for i in range(nb)]


class _Shard(torch.utils.data.Sampler):
    """This process's share of each global batch."""

    def __init__(self, batches: list[np.ndarray], d: Dist) -> None:
        self.batches = [b[d.rank::d.world].tolist() for b in batches]

    def __iter__(self):
        return iter(self.batches)

    def __len__(self) -> int:
        return len(self.batches)


def _split_loss(out) -> tuple[torch.Tensor, dict]:
    if isinstance(out, tuple):
        return out[0], dict(out[1])
    return out, {}


def batch_len(batch: dict) -> int:
    """Samples in a (local) batch: the length of ``index`` or of the first tensor."""
    if "index" in batch:
        return len(batch["index"])
    return len(next(v for v in batch.values() if torch.is_tensor(v)))


def _to(batch: dict, device: torch.device) -> dict:
    return {k: v.to(device, non_blocking=True) if torch.is_tensor(v) else v for k, v in batch.items()}


def _loader(ds: Dataset, batches, d: Dist, workers: int) -> DataLoader:
    return DataLoader(ds, batch_sampler=_Shard(batches, d), num_workers=workers)


def step_lr(optim: OptimConfig, step: int, steps: int) -> float:
    """The learning rate of global step ``step`` (0-based) of ``steps`` in the whole run
    (:class:`methods.nn.config.OptimConfig`: ``lr_schedule``); a pure function of the step, so a resumed run
    continues the schedule where it stopped."""
    if optim.lr_schedule == "cosine":
        return optim.lr * 0.5 * (1.0 + math.cos(math.pi * step / max(steps, 1)))
    return optim.lr


def _optimizer(model: nn.Module, optim: OptimConfig) -> torch.optim.Optimizer:
    return torch.optim.Adam(model.parameters(), lr=optim.lr, weight_decay=optim.weight_decay)


def _train_epoch(job: FitJob, net: nn.Module, opt, epoch: int, d: Dist, progress: bool) -> tuple[float, int, dict]:
    """One epoch; returns (mean training loss over all processes, samples seen, mean of each named term)."""
    job.train.set_epoch(epoch)
    batches = epoch_batches(len(job.train), optim=job.optim, epoch=epoch)
    net.train()
    total, count, terms = 0.0, 0, {}
    bar = tqdm(_loader(job.train, batches, d, job.num_workers), total=len(batches), file=sys.stderr,
               desc=f"{job.name} epoch {epoch + 1}/{job.optim.epochs}", unit="batch", leave=False,
               disable=None if (progress and d.main) else True, dynamic_ncols=True)
    for i, batch in enumerate(bar):
        batch = _to(batch, d.device)
        opt.zero_grad(set_to_none=True)
        loss, parts = _split_loss(job.loss(net, batch))
        if not torch.isfinite(loss):
            raise TrainingError(f"{job.name}: the loss became {loss.item()} in epoch {epoch + 1}; "
                                "lower optim.lr or check the data")
        loss.backward()
        if job.optim.grad_clip:
            nn.utils.clip_grad_norm_(net.parameters(), job.optim.grad_clip)
        for group in opt.param_groups:
            group["lr"] = step_lr(job.optim, epoch * len(batches) + i, job.optim.epochs * len(batches))
        opt.step()
        n = batch_len(batch)
        total += float(loss.detach()) * n
        count += n
        for k, v in parts.items():
            terms[k] = terms.get(k, 0.0) + float(v) * n
        bar.set_postfix(loss=f"{loss.item():.5f}")
    names = sorted(terms)
    sums = d.sum([total, count] + [terms[k] for k in names])
    total, count = sums[0], sums[1]
    return total / max(count, 1), int(count), {f"train_{k}": v / max(count, 1) for k, v in zip(names, sums[2:])}


@torch.no_grad()
def evaluate(job: FitJob, net: nn.Module, d: Dist) -> float:
    """Mean loss over every validation sample (NaN without validation data)."""
    if job.validation is None or len(job.validation) == 0:
        return float("nan")
    net.eval()
    idx = np.arange(len(job.validation))
    batches = [idx[i:i + job.optim.batch_size] for i in range(0, len(idx), job.optim.batch_size)]
    total, count = 0.0, 0
    for batch in _loader(job.validation, batches, d, job.num_workers):
        batch = _to(batch, d.device)
        total += float(_split_loss(job.loss(net, batch))[0]) * batch_len(batch)
        count += batch_len(batch)
    total, count = d.sum([total, count])
    return total / max(count, 1)


def _save_checkpoint(job: FitJob, model: nn.Module, opt, history: list[dict]) -> None:
    tensors = {f"model/{k}": v for k, v in model.state_dict().items()}
    tensors.update(optimizer_tensors(opt))
    save_tensors(job.folder / CHECKPOINT, tensors, kind="checkpoint",
                 meta={"job": job.name, "epoch": len(history), "history": history, **job.meta})


def _resume(job: FitJob, model: nn.Module, opt) -> list[dict]:
    path = job.folder / CHECKPOINT
    if not path.exists():
        return []
    f = load_tensors(path, kind="checkpoint")
    load_state(model, f.prefixed("model/"), where=path)
    load_optimizer_tensors(opt, f.tensors, where=path)
    history = list(f.meta.get("history", []))
    if len(history) > job.optim.epochs:
        raise TrainingError(f"{path}: has {len(history)} epochs, the config asks for {job.optim.epochs}")
    return history


def fit(job: FitJob, d: Dist, *, resume: bool = False, progress: bool = True) -> FitResult:
    """Train ``job.model``; see the module docstring. Returns the unwrapped, trained model."""
    if job.optim.batch_size % d.world:
        raise TrainingError(f"optim.batch_size {job.optim.batch_size} must divide by the {d.world} processes")
    model = job.model.to(d.device)
    opt = _optimizer(model, job.optim)
    history = _resume(job, model, opt) if resume else []
    start = len(history)
    net = wrap(model, d)
    if d.main:
        job.folder.mkdir(parents=True, exist_ok=True)
    for epoch in range(start, job.optim.epochs):
        t0 = time.perf_counter()
        train_loss, n, terms = _train_epoch(job, net, opt, epoch, d, progress)
        seconds = time.perf_counter() - t0
        val_loss = evaluate(job, net, d)
        history.append({"epoch": epoch + 1, "train_loss": train_loss, "val_loss": val_loss,
                        "seconds": round(seconds, 3), "samples_per_s": round(n / seconds, 2) if seconds > 0 else 0.0, **terms})
        if d.main:
            _save_checkpoint(job, model, opt, history)
            if progress:
                print(f"{job.name}: epoch {epoch + 1}/{job.optim.epochs} train loss {train_loss:.5f} "
                      f"validation loss {val_loss:.5f} ({seconds:.1f} s)", file=sys.stderr, flush=True)
        d.barrier()
    if d.main:
        write_history(job.folder, history, title=job.name)
    d.barrier()
    return FitResult(model, history, start)


def history_csv(history: list[dict]) -> str:
    buf = io.StringIO()
    extra = sorted({k for h in history for k in h} - set(HISTORY_COLUMNS))
    w = csv.DictWriter(buf, fieldnames=list(HISTORY_COLUMNS) + extra, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    w.writerows(history)
    return buf.getvalue()


def write_history(folder: Path, history: list[dict], *, title: str) -> None:
    """``history.csv`` and ``curves.png`` of a finished fit."""
    from methods.nn.plots import plot_curves

    atomic_write_text(folder / HISTORY, history_csv(history))
    plot_curves(folder / CURVES, history, title=title)


__all__ = ["FitJob", "FitResult", "fit", "seeded", "epoch_batches", "evaluate", "step_lr"]
