"""The benchmark runner: methods x datasets x frames, cached, on local processes or Dask.

:func:`run_benchmark` is the one entry point (``depthbench bench run`` is a thin parser around it).

Work unit (:class:`bench.compute.FrameTask`): one chunk of :func:`methods.run.plan_chunks` of one
dataset with every method that shares that chunk plan and lacks a cached result in it. For frame
methods (the filters) that is one frame (read once, reference planes fitted once) with all of
them; a sequence method gets its sequence (or its chunks with warm-up frames) in frame order; a
batched method its batches. A (method key, dataset checksum, frame) is computed once: its rows
are written to ``RESULTS/cache/`` as soon as the task finishes, and any later run into the same
folder reuses them; a method whose key changes (new version, parameters or weights file) is
recomputed, the others are not. A frame a method refuses stops the run
(:class:`methods.errors.FrameRejectedError`, the rule of :mod:`methods.run`): nothing is published,
the cache keeps what was computed.

The results folder (``--out``):

* missing or empty: the run is built in a temporary sibling folder and published when complete,
  so a failed run leaves nothing;
* an existing results folder (same schema version and metric parameters): the run *continues* it.
  Cached rows are reused; new cache parts are added as tasks finish; the table, manifest and
  report are replaced atomically at the end. The new table holds this run's (method, dataset)
  pairs plus the earlier runs' pairs that this run did not touch; a pair whose method key or
  dataset checksum changed is superseded (listed in the manifest's run history). This is not
  "overwriting": no computed row is lost and the cache keeps the old key's rows;
* anything else (a folder of other files, a folder of another schema version, other metric
  parameters): an error, unless ``force`` replaces it (built aside, swapped in at the end).

Executors: ``"process"`` (default; a local process pool of ``jobs`` processes, in-process when one
job or one task), ``"dask"`` (``workers`` processes of a ``LocalCluster``, or the cluster at
``scheduler``). The tasks and the table are identical whichever runs them; datasets must be
readable at the same path on Dask workers. Workers of your own cluster should not be started with
Dask's default ``MALLOC_TRIM_THRESHOLD_=65536`` (``distributed.nanny.pre-spawn-environ``): it
makes the metrics 2.5x slower (every large temporary array goes through mmap).
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
import logging
import os
import shutil
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np
import pandas as pd
from tqdm import tqdm

from align.dataset import AlignedDataset
from bench import results as R
from bench.compute import FrameOutput, FrameTask, HQSensor, preview_inputs
from bench.errors import BenchError, DatasetError, EmptyReferenceError  # noqa: F401 (re-exported)
from bench.executors import EXECUTORS, ExecutorSpec  # noqa: F401 (re-exported)
from bench.metrics import MetricConfig
from depthbench.errors import OutputExistsError
from depthbench.fsutil import publish_directory, staging_dir_for
from methods.base import Denoiser
from methods.errors import UnknownMethodError
from methods.registry import available, get, resolve_name
from methods.run import plan_chunks

log = logging.getLogger(__name__)


@dataclass
class BenchResult:
    """What :func:`run_benchmark` did.

    Attributes:
        out: the results folder.
        table: the results table (as written to ``out/results.parquet``).
        computed: (method, frame) results computed by this run.
        reused: (method, frame) results taken from the cache.
        superseded: ``"method on dataset"`` pairs whose earlier rows this run replaced.
        report: the leaderboard's paths (None with ``report=False``).
    """

    out: Path
    table: pd.DataFrame
    computed: int
    reused: int
    superseded: list[str] = field(default_factory=list)
    report: object | None = None

    @property
    def table_path(self) -> Path:
        return self.out / R.TABLE


# ----------------------------------------------------------------------------------- inputs
def resolve_methods(methods: str | Sequence[str | Denoiser],
                    params: dict[str, dict] | None = None) -> list[Denoiser]:
    """``"all"``, a comma-separated string, or a list of names / Denoiser instances -> instances.

    ``params`` maps a method name (or alias) to parameters for the methods named by string, e.g.
    ``{"ssdd_unet": {"weights": "run/model.safetensors"}}``. ``"all"`` is every registered method
    that runs without parameters, plus the learned ones whose weights ``params`` names.

    Raises :class:`methods.errors.UnknownMethodError` (one line, listing the known names).
    """
    try:
        params = {resolve_name(n): dict(p) for n, p in (params or {}).items()}
    except UnknownMethodError as exc:
        raise UnknownMethodError(f"--param: {exc}") from None
    if isinstance(methods, str):
        names = [m.strip() for m in methods.split(",") if m.strip()]
        if names == ["all"]:
            names = [n for n, cls in available().items() if not cls.needs_weights() or n in params]
        methods = names
    out: list[Denoiser] = []
    for m in methods:
        if isinstance(m, str):
            try:
                m = resolve_name(m)   # names or the seed's aliases (bf, jbf, rgf)
            except UnknownMethodError as exc:
                raise UnknownMethodError(f"--methods: {exc}") from None
            m = get(m, **params.pop(m, {}))
        out.append(m)
    if params:
        raise BenchError(f"--param: method {next(iter(params))!r} is not among the methods to run")
    if not out:
        raise BenchError("--methods: no method given (use 'all' or names such as raw,bf)")
    keys = [m.key for m in out]
    names = [m.name for m in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise BenchError(f"--methods: method {dup[0]!r} given twice ({', '.join(k for k in keys if k.startswith(dup[0] + '@'))})")
    return out


def resolve_datasets(paths: Iterable[str | os.PathLike | AlignedDataset]) -> list[AlignedDataset]:
    """Aligned datasets from paths; a folder of aligned datasets stands for all of them (sorted)."""
    out: list[AlignedDataset] = []
    for p in paths:
        if isinstance(p, AlignedDataset):
            out.append(p)
            continue
        p = Path(p)
        if not p.exists():
            raise DatasetError(f"{p}: no such aligned dataset")
        if p.is_dir() and not (p / "aligned.json").exists():
            subs = sorted(d for d in p.iterdir() if d.is_dir() and (d / "aligned.json").exists())
            if not subs:
                raise DatasetError(f"{p}: not an aligned dataset (no aligned.json) and holds none")
            out += [AlignedDataset(d) for d in subs]
            continue
        out.append(AlignedDataset(p))
    if not out:
        raise DatasetError("no dataset given")
    for ds in out:
        ds.check_frame_files()   # every frame file present and readable before the long work
    seen: dict[str, AlignedDataset] = {}
    for ds in out:
        if len(ds) == 0:
            raise DatasetError(f"{ds.root}: the aligned dataset has no frames")
        other = seen.get(ds.name)
        if other is not None and other.checksum != ds.checksum:
            raise DatasetError(f"two datasets named {ds.name!r} ({other.root}, {ds.root}): names must be unique in a run")
        seen[ds.name] = ds
    return list({ds.checksum: ds for ds in out}.values())


def preview_frame(ds: AlignedDataset) -> int:
    """The frame of the qualitative figure: the middle one, or the frame with colour nearest to it."""
    mid = len(ds) // 2
    coloured = [i for i, r in enumerate(ds.rows) if r["lq_color_file"]]
    return min(coloured, key=lambda i: (abs(i - mid), i)) if coloured else mid


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


# ----------------------------------------------------------------------------------- folder
def _prepare_out(out: Path, config: MetricConfig, force: bool) -> tuple[Path, dict | None, bool]:
    """Where to build the run: ``(work folder, previous manifest or None, staged?)``."""
    exists = out.exists() and (not out.is_dir() or any(out.iterdir()))
    if exists and not force:
        if not out.is_dir():
            raise OutputExistsError(f"{out}: exists and is not a results folder; pass --force to replace it")
        if not (out / R.MANIFEST).exists():
            raise OutputExistsError(f"{out}: exists and is not a depthbench results folder (no {R.MANIFEST}); "
                                    "choose another --out or pass --force to replace it")
        meta = R.read_manifest(out)   # raises on another schema version
        if meta["metrics"] != config.to_dict():
            raise BenchError(f"{out}: computed with metric parameters {meta['metrics']}, this run asks for "
                             f"{config.to_dict()}; use another --out or --force")
        if meta.get("table"):
            R.load_results(out)      # the table must be readable too
        return out, meta, False
    out.parent.mkdir(parents=True, exist_ok=True)
    return staging_dir_for(out), None, True


# ----------------------------------------------------------------------------------- the run
@dataclass
class RunPlan:
    """One benchmark run, decided before any method runs.

    Attributes:
        work: the folder being written (``out`` itself when continuing it, else a staging sibling).
        out: the results folder the user named.
        datasets, methods: what is scored (``methods`` includes :class:`HQSensor` for simulated data).
        config: metric parameters.
        executor: where tasks run.
        prev_meta: the manifest of the results folder being continued (None: a new folder).
        started: ISO time the run started.
        progress: tqdm bar on stderr (None: only when stderr is a terminal).
        threads_per_task: CPU threads a task may use (None: the executor's share).
    """

    work: Path
    out: Path
    datasets: list[AlignedDataset]
    methods: list
    config: MetricConfig
    executor: ExecutorSpec
    prev_meta: dict | None = None
    started: str = ""
    progress: bool | None = None
    threads_per_task: int | None = None


@dataclass
class _Schedule:
    """The tasks of a run and the results it needs: (method, dataset, frame) triples, how many are cached."""

    tasks: list[FrameTask] = field(default_factory=list)
    needed: list[tuple] = field(default_factory=list)
    reused: int = 0

    @property
    def n_todo(self) -> int:
        return sum(len(t.todo) for t in self.tasks)


def run_benchmark(datasets: Sequence[str | os.PathLike | AlignedDataset], methods: str | Sequence[str | Denoiser],
                  out: str | os.PathLike, *, config: MetricConfig = MetricConfig(), executor: str = "process",
                  jobs: int | None = None, workers: int | None = None, scheduler: str | None = None,
                  force: bool = False, progress: bool | None = None, report: bool = True,
                  threads_per_task: int | None = None, params: dict[str, dict] | None = None) -> BenchResult:
    """Score ``methods`` on every frame of ``datasets``; write (or continue) the results folder ``out``.

    Args:
        datasets: aligned dataset folders (a folder of aligned datasets stands for all of them).
        methods: ``"all"``, ``"raw,bf"``, or a list of names / :class:`methods.base.Denoiser` instances
            (``"all"``: every registered method that runs without parameters, and the learned methods
            whose weights ``params`` names).
        out: the results folder (see the module docstring for how an existing one is continued).
        config: metric parameters (part of the folder's identity).
        executor: ``"process"`` (local processes) or ``"dask"``; ``workers``/``scheduler`` imply Dask.
        jobs: local processes (default: CPU count; 1 runs in this process).
        workers: Dask ``LocalCluster`` worker processes.
        scheduler: address of a running Dask scheduler (``tcp://host:8786``).
        force: replace an existing folder that cannot be continued (and drop its cache).
        progress: tqdm bar on stderr (None: only when stderr is a terminal).
        report: write the leaderboard (Markdown, HTML, figures) into ``out``.
        threads_per_task: CPU threads a task may use (numba kernels, plane fit); default: the CPU count
            divided among the local workers (library defaults on a remote cluster). Results do not
            depend on it.
        params: parameters of methods named by string, by method name, e.g.
            ``{"ssdd_unet": {"weights": "run/model.safetensors"}}`` (see :func:`resolve_methods`).

    Returns:
        A :class:`BenchResult`.

    Raises:
        BenchError (and the stage errors it wraps, e.g. :class:`methods.errors.FrameRejectedError`
        for a frame a method refuses): one line naming the argument or file.
    """
    out = Path(out)
    spec = ExecutorSpec(executor=executor, jobs=jobs, workers=workers, scheduler=scheduler).check()
    method_list = resolve_methods(methods, params)
    ds_list = resolve_datasets(datasets)
    for m in method_list:
        for ds in ds_list:
            m.check_dataset(ds)     # e.g. a learned method refusing its own training data, before any work
    if any(ds.simulated for ds in ds_list):
        method_list = method_list + [HQSensor()]
    work, prev_meta, staged = _prepare_out(out, config, force)
    plan = RunPlan(work=work, out=out, datasets=ds_list, methods=method_list, config=config, executor=spec,
                   prev_meta=prev_meta, started=_now(), progress=progress, threads_per_task=threads_per_task)
    try:
        result = _run(plan)
        if report:
            from bench.report import write_report
            result.report = write_report(work, table=result.table)
        if staged:
            publish_directory(work, out)
            if result.report is not None:
                result.report = result.report.moved(work, out)
        result.out = out
        return result
    except BaseException:
        if staged:
            shutil.rmtree(work, ignore_errors=True)
        raise


def _chunk_signature(method) -> tuple:
    """Methods with equal signatures are fed the same chunks and share tasks."""
    n = method.needs
    return (n.sequence, n.chunk_frames, n.warmup_frames, n.batch_size)


def _cached(plan: RunPlan, method, ds: AlignedDataset, frame: int, preview: int) -> bool:
    return R.cache_part(plan.work, method.key, ds.checksum, frame).exists() and (
        frame != preview or R.preview_path(plan.work, ds.checksum, method.key).exists())


def _schedule(plan: RunPlan) -> _Schedule:
    """Per dataset and chunk (:func:`methods.run.plan_chunks`), a task with every method that lacks a cached result."""
    sched = _Schedule()
    for ds in plan.datasets:
        mid = preview_frame(ds)
        groups: dict[tuple, list] = {}
        for m in plan.methods:
            if not isinstance(m, HQSensor) or ds.simulated:
                groups.setdefault(_chunk_signature(m), []).append(m)
        for group in groups.values():
            for chunk in plan_chunks(group[0], len(ds)):
                cached = {(m.key, i) for m in group for i in chunk.frames if _cached(plan, m, ds, i, mid)}
                sched.needed += [(m, ds, i) for i in chunk.frames for m in group]
                sched.reused += len(cached)
                todo = tuple(m for m in group if any((m.key, i) not in cached for i in chunk.frames))
                if todo:
                    sched.tasks.append(FrameTask(
                        dataset_root=str(ds.root.resolve()), dataset_checksum=ds.checksum, dataset_name=ds.name,
                        sequence=ds.sequence, frames=chunk.frames, warmup=chunk.warmup, methods=todo,
                        config=plan.config, cached=frozenset(cached),
                        preview=mid if mid in chunk.frames else None))
    return sched


def _run(plan: RunPlan) -> BenchResult:
    sched = _schedule(plan)
    ex = plan.executor.make(len(sched.tasks))
    threads = plan.threads_per_task or ex.threads
    if threads is not None:
        sched.tasks = [dataclasses.replace(t, threads=threads) for t in sched.tasks]
    log.debug("bench: %d results to compute, %d cached, on %s", sched.n_todo, sched.reused, ex.name)
    for ds in plan.datasets:   # the inputs of the qualitative figure
        p = R.preview_path(plan.work, ds.checksum)
        if not p.exists():
            R.save_npz(p, **preview_inputs(ds, preview_frame(ds)))
    _execute(plan, ex, sched)

    # this run's rows, from the cache
    parts = [R.cache_part(plan.work, m.key, ds.checksum, i) for m, ds, i in sched.needed]
    new = R.read_parts([p for p in parts if p.exists()])
    _check_parts(new, sched.needed, plan.out)
    _check_references(new, plan.datasets)
    table, superseded = _merge_earlier(plan, new)
    digest = R.write_table(table, plan.work / R.TABLE)
    record = {"executor": ex.name, "computed": sched.n_todo, "reused": sched.reused, "superseded": superseded}
    _write_manifest(plan, table, digest, record)
    if superseded:
        log.debug("bench: superseded earlier rows of %s", "; ".join(superseded))
    return BenchResult(out=plan.out, table=table, computed=sched.n_todo, reused=sched.reused, superseded=superseded)


def _execute(plan: RunPlan, ex, sched: _Schedule) -> None:
    """Run the tasks; write each result's cache part (and preview) as soon as its task returns."""
    bar = tqdm(total=sched.n_todo, desc="bench", unit="result", file=sys.stderr, dynamic_ncols=True,
               disable=(None if plan.progress is None else not plan.progress))

    def on_done(task: FrameTask, output: FrameOutput) -> None:
        for key, depth in output.previews.items():
            R.save_npz(R.preview_path(plan.work, task.dataset_checksum, key), depth=depth,
                       method_key=np.array(key), frame=np.array(task.preview))
        for (key, frame), rows in output.rows.items():
            part = R.cache_part(plan.work, key, task.dataset_checksum, frame)
            part.parent.mkdir(parents=True, exist_ok=True)
            R.write_table(rows, part)
        bar.update(len(task.todo))

    try:
        if sched.tasks:
            ex.run(sched.tasks, on_done)
    finally:
        bar.close()


def _merge_earlier(plan: RunPlan, new: pd.DataFrame) -> tuple[pd.DataFrame, list[str]]:
    """This run's rows plus earlier runs' rows of (method, dataset) pairs this run does not touch."""
    if plan.prev_meta is None or not plan.prev_meta.get("table"):
        return R.sort_rows(new), []
    old = R.load_results(plan.work)
    pairs_new = set(zip(new["method"], new["dataset"]))
    touched = pd.Series([p in pairs_new for p in zip(old["method"], old["dataset"])], index=old.index, dtype=bool)
    old_pairs = old.loc[touched, ["method", "method_key", "dataset", "dataset_checksum"]].drop_duplicates()
    new_ids = set(zip(new["method_key"], new["dataset_checksum"]))
    superseded = sorted({f"{r.method_key} on {r.dataset}" for r in old_pairs.itertuples()
                         if (r.method_key, r.dataset_checksum) not in new_ids})
    return R.sort_rows(pd.concat([old.loc[~touched], new], ignore_index=True)), superseded


def _check_parts(df: pd.DataFrame, needed, out: Path) -> None:
    """Every needed (method key, dataset, frame) has rows with matching identity (guards the cache)."""
    have = set(zip(df["method_key"], df["dataset_checksum"], df["frame"]))
    for m, ds, i in needed:
        if (m.key, ds.checksum, i) not in have:
            raise BenchError(f"{R.cache_part(out, m.key, ds.checksum, i)}: cache part missing or holds other rows "
                             f"(method {m.key}, dataset {ds.name}, frame {i}); delete it or rerun with --force")


def _check_references(df: pd.DataFrame, ds_list) -> None:
    hq = df[(df["reference"] == "hq") & (df["metric"] == "n_reference")]
    for ds in ds_list:
        v = hq.loc[hq["dataset_checksum"] == ds.checksum, "value"]
        if len(v) and not (v > 0).any():
            raise EmptyReferenceError(f"{ds.root}: the reference depth (hq_depth) has no valid pixel"
                                      f"{' inside the ROI' if _has_roi(ds) else ''} in any of its {len(ds)} frames; "
                                      "nothing to score against")
        empty = int((v == 0).sum())
        if empty:
            log.warning("%s: %d of %d frames have an empty reference (their errors are NaN)", ds.root, empty, len(ds))


def _has_roi(ds: AlignedDataset) -> bool:
    return any(r["roi_file"] for r in ds.rows)


def _depthbench_version() -> str:
    try:
        from importlib.metadata import version
        return version("depthbench")
    except Exception:   # noqa: BLE001 - not installed as a distribution
        return "unknown"


def _write_manifest(plan: RunPlan, table: pd.DataFrame, digest: str, record: dict) -> None:
    """``results.json``: this run's datasets and methods merged with the earlier runs' still in the table."""
    prev = plan.prev_meta or {}
    datasets = {d["checksum"]: d for d in prev.get("datasets", [])}
    for ds in plan.datasets:
        datasets[ds.checksum] = {"name": ds.name, "sequence": ds.sequence, "checksum": ds.checksum,
                                 "path": str(ds.root.resolve()), "frames": len(ds), "simulated": bool(ds.simulated),
                                 "preview_frame": preview_frame(ds)}
    present = set(table["dataset_checksum"].unique())
    methods = {m["key"]: m for m in prev.get("methods", [])}
    methods.update({m.key: m.describe() for m in plan.methods})
    keys = set(table["method_key"].unique())
    run = {"started": plan.started, "finished": _now(), "executor": record["executor"],
           "computed": int(record["computed"]), "reused": int(record["reused"]),
           "methods": [m.key for m in plan.methods], "datasets": [ds.name for ds in plan.datasets],
           "superseded": record["superseded"]}
    meta = {"format": R.FORMAT, "schema_version": R.SCHEMA_VERSION, "metrics": plan.config.to_dict(),
            "table": {"file": R.TABLE, "sha256": digest, "rows": int(len(table))},
            "datasets": [d for c, d in datasets.items() if c in present],
            "methods": [m for k, m in methods.items() if k in keys],
            "runs": prev.get("runs", []) + [run], "depthbench_version": _depthbench_version()}
    R.write_manifest(plan.work, meta)
