"""``depthbench methods train``: the library entry point that turns a manifest and a config into weights.

:func:`train_method` checks everything that can be checked before any file is written (the
method has a trainer, the config file parses with only known keys, the manifest's datasets are
present and unchanged, an existing run folder is resumed only when asked, its checkpoints are
readable), then creates the run folder and hands a :class:`RunContext` to the method's trainer.

The run folder (``--out RUN``)::

    RUN/
      run.json            method, config file, manifest (name, sha256), git revision, device,
                          processes, status, timings, weights files with their sha256
      config.toml         the resolved config (every field): the run can be repeated from it
      <stage>/            one folder per network trained: checkpoint.safetensors (resume),
                          history.csv, curves.png (learning curves)
      <method>.safetensors   the weights inference loads (``--param weights=RUN/<method>.safetensors``)

Trainers register with :func:`register_trainer`; see ``/work/notes/TRAINING.md`` and
``methods/ssdd/train.py`` for an example.
"""
from __future__ import annotations

import datetime as _dt
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from depthbench.errors import OutputExistsError
from depthbench.fsutil import atomic_write_json, atomic_write_text, read_json, sha256_file
from methods.errors import TrainingError, UnknownMethodError
from methods.nn import checkpoint as ckpt
from methods.nn.config import load_config, to_dict, to_toml
from methods.nn.distributed import Dist, setup, teardown
from methods.nn.manifest import TrainingManifest, read_manifest
from methods.nn.trainer import CHECKPOINT, FitJob, FitResult, fit

RUN_JSON = "run.json"
RUN_FORMAT = "depthbench.training-run"


@dataclass(frozen=True)
class Trainer:
    """How to train method(s): ``run(ctx)`` returns ``{method name: weights file}``.

    ``family`` names the folder of built-in configs (``methods/configs/<family>/``); ``config`` is
    the config dataclass the TOML file must fit.
    """

    name: str
    family: str
    config: type
    run: Callable[["RunContext"], dict[str, Path]]
    description: str = ""


_TRAINERS: dict[str, Trainer] = {}
#: Modules that register trainers (imported by :func:`trainers`; add yours here).
TRAINER_MODULES = ("methods.ssdd.train", "methods.ddrnet.train", "methods.ddd.train")


def register_trainer(trainer: Trainer) -> Trainer:
    _TRAINERS[trainer.name] = trainer
    return trainer


def trainers() -> dict[str, Trainer]:
    """Every registered trainer by name (importing the method modules registers them)."""
    import importlib

    for name in TRAINER_MODULES:
        importlib.import_module(name)
    return dict(_TRAINERS)


def git_revision() -> str:
    """``git describe``-like identity of the code: commit hash, ``+dirty`` with local changes, or ``unknown``."""
    root = Path(__file__).resolve().parents[2]
    try:
        rev = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                             timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return rev + ("+dirty" if dirty else "")


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


@dataclass
class RunContext:
    """What a trainer gets: the checked inputs, the run folder and the process group."""

    method: str
    out: Path
    config: Any
    config_file: Path
    manifest: TrainingManifest
    dist: Dist
    resume: bool = False
    progress: bool = True
    revision: str = "unknown"
    stages: dict[str, dict] = field(default_factory=dict)

    def fit(self, job: FitJob) -> FitResult:
        """Train one network (see :func:`methods.nn.trainer.fit`) and note it in ``run.json``."""
        result = fit(job, self.dist, resume=self.resume, progress=self.progress)
        self.stages[job.name] = {"folder": str(job.folder.relative_to(self.out)), "epochs": len(result.history),
                                 "resumed_from_epoch": result.resumed_from,
                                 "final": result.history[-1] if result.history else None,
                                 "samples_per_s": result.samples_per_s}
        return result

    def weights_meta(self, method: str, **extra) -> dict:
        """The metadata every weights file carries: method, config, data provenance, code revision."""
        return {"method": method, "config": to_dict(self.config), "config_file": str(self.config_file),
                "training": self.manifest.provenance(), "git_revision": self.revision, "created": _now(), **extra}

    def save_weights(self, method: str, tensors: dict, **extra) -> Path:
        """Write ``RUN/<method>.safetensors`` (main process only; the others wait)."""
        path = self.out / f"{method}.safetensors"
        if self.dist.main:
            ckpt.save_tensors(path, tensors, kind="weights", meta=self.weights_meta(method, **extra))
        self.dist.barrier()
        return path


def _check_out(out: Path, *, method: str, resume: bool, force: bool) -> None:
    if not out.exists() or (out.is_dir() and not any(out.iterdir())):
        if resume:
            raise TrainingError(f"{out}: nothing to resume (no run folder)")
        return
    if resume:
        meta = read_json(out / RUN_JSON, error=TrainingError, missing=" (not a training run folder)")
        if meta.get("method") != method:
            raise TrainingError(f"{out}: a run of {meta.get('method')!r}, not {method!r}; cannot resume it")
        for p in sorted(out.rglob(CHECKPOINT)):
            ckpt.load_tensors(p, kind="checkpoint")      # corrupt checkpoints fail before anything is written
        return
    if not force:
        raise OutputExistsError(f"{out}: run folder exists; pass --resume to continue it or --force to replace it")


def _run_record(ctx: RunContext, *, status: str, started: str, seconds: float, weights: dict[str, Path]) -> dict:
    return {"format": RUN_FORMAT, "format_version": "1.0", "method": ctx.method, "status": status,
            "config_file": str(ctx.config_file), "manifest": ctx.manifest.provenance(("train", "validation", "test")),
            "git_revision": ctx.revision, "device": str(ctx.dist.device), "processes": ctx.dist.world,
            "python": sys.version.split()[0], "started": started, "finished": _now() if status != "running" else None,
            "seconds": round(seconds, 2), "stages": ctx.stages,
            "weights": {m: {"file": p.name, "sha256": sha256_file(p)} for m, p in weights.items() if p.exists()}}


@dataclass
class TrainResult:
    """What :func:`train_method` produced: the run folder and ``{method: weights file}``."""

    out: Path
    weights: dict[str, Path]
    seconds: float
    stages: dict[str, dict]


def train_method(name: str, *, dataset: str | os.PathLike, config: str | os.PathLike, out: str | os.PathLike,
                 device: str | None = None, resume: bool = False, force: bool = False,
                 progress: bool = True) -> TrainResult:
    """Train method ``name`` on the training manifest ``dataset`` with ``config`` into run folder ``out``.

    Under ``torchrun`` every process calls this; they train together (DDP) and only rank 0 writes.
    Raises :class:`methods.errors.TrainingError` (one line) before writing anything when an input is bad.
    """
    available = trainers()
    if name not in available:
        raise UnknownMethodError(f"no trainer for {name!r} (trainable: {', '.join(available) or 'none'})")
    trainer = available[name]
    cfg, cfg_file = load_config(config, trainer.config, family=trainer.family)
    manifest = read_manifest(dataset)
    if not manifest.split("train"):
        raise TrainingError(f"{manifest.path}: no dataset in the 'train' split")
    out = Path(out)
    _check_out(out, method=name, resume=resume, force=force)
    d = setup(device)
    try:
        return _train(trainer, cfg, cfg_file, manifest, out, d, resume=resume, force=force, progress=progress)
    finally:
        teardown(d)


def _train(trainer: Trainer, cfg, cfg_file: Path, manifest: TrainingManifest, out: Path, d: Dist, *, resume: bool,
           force: bool, progress: bool) -> TrainResult:
    if d.main:
        if force and not resume and out.exists():
            shutil.rmtree(out) if out.is_dir() else out.unlink()
        out.mkdir(parents=True, exist_ok=True)
    d.barrier()
    ctx = RunContext(trainer.name, out, cfg, cfg_file, manifest, d, resume=resume, progress=progress,
                     revision=git_revision())
    started, t0 = _now(), time.perf_counter()
    if d.main:
        atomic_write_text(out / "config.toml", f"# resolved config of {trainer.name} (from {cfg_file})\n" + to_toml(cfg))
        atomic_write_json(out / RUN_JSON, _run_record(ctx, status="running", started=started, seconds=0, weights={}))
    try:
        weights = trainer.run(ctx)
    except BaseException:
        if d.main:
            atomic_write_json(out / RUN_JSON, _run_record(ctx, status="failed", started=started,
                                                          seconds=time.perf_counter() - t0, weights={}))
        raise
    seconds = time.perf_counter() - t0
    if d.main:
        atomic_write_json(out / RUN_JSON, _run_record(ctx, status="done", started=started, seconds=seconds,
                                                      weights=weights))
    return TrainResult(out, weights, seconds, ctx.stages)
