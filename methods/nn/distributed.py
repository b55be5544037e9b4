"""Multi-process training with PyTorch's DistributedDataParallel, as started by ``torchrun``.

``torchrun --nproc_per_node N -m depthbench methods train ...`` starts N copies of the command with
``RANK``/``WORLD_SIZE``/``LOCAL_RANK`` set; :func:`setup` joins them into one process group (gloo on
CPU, NCCL on CUDA). A plain run (no ``WORLD_SIZE`` or ``WORLD_SIZE=1``) is a group of one and
uses no process group at all.

Every process draws the same global batch (:mod:`methods.nn.trainer`) and takes its share
(``batch[rank::world]``); DDP averages the gradients, so N processes with a global batch B step
exactly like one process with batch B (to float rounding in the all-reduce). Only rank 0 writes files.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import torch
import torch.distributed as dist

from methods.errors import TrainingError


@dataclass(frozen=True)
class Dist:
    """This process's place in the group: ``rank`` of ``world`` processes, on ``device``."""

    rank: int = 0
    world: int = 1
    local_rank: int = 0
    device: torch.device = torch.device("cpu")

    @property
    def main(self) -> bool:
        """True in the process that writes files and shows progress."""
        return self.rank == 0

    @property
    def active(self) -> bool:
        return self.world > 1

    def barrier(self) -> None:
        if self.active:
            dist.barrier()

    def sum(self, values: list[float]) -> list[float]:
        """Element-wise sum of ``values`` over all processes (identity for one process)."""
        if not self.active:
            return list(values)
        t = torch.tensor(values, dtype=torch.float64, device=self.device if self.device.type == "cuda" else "cpu")
        dist.all_reduce(t)
        return t.tolist()


def resolve_device(name: str | None = None, *, local_rank: int = 0) -> torch.device:
    """``None``/``"auto"``: CUDA when present, else CPU; ``"cpu"``, ``"cuda"``, ``"cuda:1"`` as given."""
    if name in (None, "", "auto"):
        name = "cuda" if torch.cuda.is_available() else "cpu"
    try:
        device = torch.device(name)
    except RuntimeError:
        raise TrainingError(f"device {name!r} is not a torch device (auto, cpu, cuda, cuda:N)") from None
    if device.type == "cuda":
        if not torch.cuda.is_available():
            raise TrainingError(f"device {name!r}: CUDA is not available on this machine")
        if device.index is None:
            device = torch.device("cuda", local_rank % torch.cuda.device_count())
    elif device.type != "cpu":
        raise TrainingError(f"device {name!r}: only cpu and cuda are supported")
    return device


def setup(device: str | None = None) -> Dist:
    """Join the torchrun process group if there is one; returns this process's :class:`Dist`."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    rank = int(os.environ.get("RANK", "0"))
    local_rank = int(os.environ.get("LOCAL_RANK", "0"))
    dev = resolve_device(device, local_rank=local_rank)
    if world > 1 and not dist.is_initialized():
        backend = "nccl" if dev.type == "cuda" else "gloo"
        if dev.type == "cuda":
            torch.cuda.set_device(dev)
        dist.init_process_group(backend=backend)
    return Dist(rank, world, local_rank, dev)


def teardown(d: Dist) -> None:
    """Leave the process group (no-op for one process)."""
    if d.active and dist.is_initialized():
        dist.destroy_process_group()


def wrap(model: torch.nn.Module, d: Dist) -> torch.nn.Module:
    """The model as trained: in DDP when several processes train it."""
    model = model.to(d.device)
    if not d.active:
        return model
    from torch.nn.parallel import DistributedDataParallel

    ids = [d.device.index] if d.device.type == "cuda" else None
    return DistributedDataParallel(model, device_ids=ids)


def unwrap(model: torch.nn.Module) -> torch.nn.Module:
    """The network inside :func:`wrap`'s result (the model itself when it was not wrapped)."""
    return getattr(model, "module", model)
