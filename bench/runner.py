"""The benchmark runner: methods x datasets x frames, cached, on local processes or Dask.

:func:`run_benchmark` is the one entry point (``depthbench bench run`` is a thin parser around it).

Work unit: one frame of one dataset (read once, reference planes fitted once), with every method
whose rows for that frame are not cached yet. A (method key, dataset checksum, frame) is computed
once: its rows are written to ``RESULTS/cache/`` as soon as the task finishes, and any later run
into the same folder reuses them; a method whose key changes (new version or parameters) is
recomputed, the others are not.

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
import multiprocessing
import os
import shutil
import sys
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np
import pandas as pd
from tqdm import tqdm

from align.dataset import AlignedDataset
from bench import results as R
from bench.compute import FrameOutput, FrameTask, HQSensor, compute_frame, preview_inputs
from bench.errors import BenchError, DatasetError, EmptyReferenceError  # noqa: F401 (re-exported)
from bench.metrics import MetricConfig
from depthbench.errors import OutputExistsError
from depthbench.fsutil import publish_directory, staging_dir_for
from methods.base import Denoiser
from methods.registry import available, get
from methods.errors import UnknownMethodError

log = logging.getLogger(__name__)

EXECUTORS = ("process", "dask")
#: Short names of the seed report (Table I) for the registered filters.


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
def resolve_methods(methods: str | Sequence[str | Denoiser]) -> list[Denoiser]:
    """``"all"``, a comma-separated string, or a list of names / Denoiser instances -> instances.

    Raises :class:`methods.errors.UnknownMethodError` (one line, listing the known names).
    """
    if isinstance(methods, str):
        names = [m.strip() for m in methods.split(",") if m.strip()]
        if names == ["all"]:   # every method that runs without arguments (a learned one needs its weights named)
            return [cls() for cls in available().values() if not cls.needs_weights()]
        methods = names
    out: list[Denoiser] = []
    for m in methods:
        if isinstance(m, str):
            try:
                m = get(m)  # names or the seed's aliases (bf, jbf, rgf)
            except UnknownMethodError as exc:
                raise UnknownMethodError(f"--methods: {exc}") from None
        out.append(m)
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


# ----------------------------------------------------------------------------------- executors
def _share(processes: int) -> int:
    """CPU threads each of ``processes`` local worker processes may use."""
    return max(1, (os.cpu_count() or 1) // max(1, processes))


class _Serial:
    name = "serial"
    threads = _share(1)

    def run(self, tasks, on_done):
        for t in tasks:
            on_done(t, compute_frame(t))


class _Processes:
    def __init__(self, jobs: int) -> None:
        self.jobs = jobs
        self.name = f"process x{jobs}"
        self.threads = _share(jobs)

    def run(self, tasks, on_done):
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["bench.compute"])
        ex = ProcessPoolExecutor(max_workers=self.jobs, mp_context=ctx)
        try:
            pending = {ex.submit(compute_frame, t): t for t in tasks}
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for f in done:
                    on_done(pending.pop(f), f.result())
        finally:
            ex.shutdown(wait=True, cancel_futures=True)


class _Dask:
    def __init__(self, workers: int | None, scheduler: str | None) -> None:
        self.workers, self.scheduler = workers, scheduler
        self.name = f"dask {scheduler}" if scheduler else f"dask LocalCluster x{workers}"
        self.threads = None if scheduler else _share(workers)   # a remote cluster's machines are not ours to size

    def run(self, tasks, on_done):
        from distributed import Client, LocalCluster, as_completed

        cluster = None
        try:
            if self.scheduler:
                try:
                    client = Client(self.scheduler, timeout="10s")
                except (OSError, TimeoutError) as exc:
                    raise BenchError(f"--scheduler {self.scheduler}: cannot connect ({exc})") from None
            else:
                import dask

                # Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_=65536, which sends every large
                # numpy temporary through mmap/munmap: the metrics then take 2.5x the CPU. Not here.
                env = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
                env.pop("MALLOC_TRIM_THRESHOLD_", None)
                with dask.config.set({"distributed.nanny.pre-spawn-environ": env}):
                    cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                           dashboard_address=None, silence_logs=logging.ERROR)
                client = Client(cluster)
        except ValueError as exc:
            raise BenchError(f"--scheduler {self.scheduler}: {exc}") from None
        try:
            futures = {client.submit(compute_frame, t, key=f"bench-{t.dataset_checksum[:16]}-{t.frame:06d}-"
                                     f"{R.short('|'.join(m.key for m in t.methods))}", pure=False): t for t in tasks}
            try:
                for f in as_completed(list(futures)):
                    on_done(futures[f], f.result())
            finally:
                client.cancel(list(futures))
        finally:
            client.close()
            if cluster is not None:
                cluster.close()


def _executor(executor: str, jobs: int | None, workers: int | None, scheduler: str | None, n_tasks: int):
    if executor not in EXECUTORS:
        raise BenchError(f"executor must be one of {', '.join(EXECUTORS)}, got {executor!r}")
    if workers is not None and workers < 1:
        raise BenchError(f"--workers must be at least 1, got {workers}")
    if jobs is not None and jobs < 1:
        raise BenchError(f"--jobs must be at least 1, got {jobs}")
    if executor == "dask" or workers is not None or scheduler is not None:
        if workers is not None and scheduler is not None:
            raise BenchError("give --workers (a local Dask cluster) or --scheduler (an existing one), not both")
        return _Dask(workers or os.cpu_count() or 1, scheduler)
    jobs = min(jobs or os.cpu_count() or 1, n_tasks)
    return _Serial() if jobs <= 1 else _Processes(jobs)


# ----------------------------------------------------------------------------------- the run
def run_benchmark(datasets: Sequence[str | os.PathLike | AlignedDataset], methods: str | Sequence[str | Denoiser],
                  out: str | os.PathLike, *, config: MetricConfig = MetricConfig(), executor: str = "process",
                  jobs: int | None = None, workers: int | None = None, scheduler: str | None = None,
                  force: bool = False, progress: bool | None = None, report: bool = True,
                  threads_per_task: int | None = None) -> BenchResult:
    """Score ``methods`` on every frame of ``datasets``; write (or continue) the results folder ``out``.

    Args:
        datasets: aligned dataset folders (a folder of aligned datasets stands for all of them).
        methods: ``"all"``, ``"raw,bf"``, or a list of names / :class:`methods.base.Denoiser` instances.
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

    Returns:
        A :class:`BenchResult`.

    Raises:
        BenchError (and the stage errors it wraps): one line naming the argument or file.
    """
    out = Path(out)
    _executor(executor, jobs, workers, scheduler, 1)     # argument errors before anything is read or written
    method_list = resolve_methods(methods)
    ds_list = resolve_datasets(datasets)
    if any(ds.simulated for ds in ds_list):
        method_list = method_list + [HQSensor()]
    work, prev_meta, staged = _prepare_out(out, config, force)
    started = _now()
    try:
        result = _run(work, out, ds_list, method_list, config, prev_meta, started,
                      executor, jobs, workers, scheduler, progress, threads_per_task)
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


def _run(work: Path, out: Path, ds_list, method_list, config, prev_meta, started, executor, jobs, workers,
         scheduler, progress, threads_per_task=None) -> BenchResult:
    # plan: per (dataset, frame) the methods without a cache part
    tasks: list[FrameTask] = []
    needed: list[tuple[Denoiser, AlignedDataset, int]] = []
    reused = 0
    for ds in ds_list:
        mid = preview_frame(ds)
        for i in range(len(ds)):
            todo = []
            for m in method_list:
                if isinstance(m, HQSensor) and not ds.simulated:
                    continue
                needed.append((m, ds, i))
                if R.cache_part(work, m.key, ds.checksum, i).exists() and (
                        i != mid or R.preview_path(work, ds.checksum, m.key).exists()):
                    reused += 1
                else:
                    todo.append(m)
            if todo:
                tasks.append(FrameTask(str(ds.root.resolve()), ds.checksum, ds.name, ds.sequence, i, tuple(todo),
                                       config, preview=(i == mid)))
    n_todo = sum(len(t.methods) for t in tasks)
    ex = _executor(executor, jobs, workers, scheduler, max(len(tasks), 1))
    threads = threads_per_task or ex.threads
    if threads is not None:
        tasks = [dataclasses.replace(t, threads=threads) for t in tasks]
    log.debug("bench: %d results to compute, %d cached, on %s", n_todo, reused, ex.name)
    for ds in ds_list:   # the inputs of the qualitative figure
        p = R.preview_path(work, ds.checksum)
        if not p.exists():
            R.save_npz(p, **preview_inputs(ds, preview_frame(ds)))

    bar = tqdm(total=n_todo, desc="bench", unit="result", disable=(None if progress is None else not progress),
               file=sys.stderr, dynamic_ncols=True)

    def on_done(task: FrameTask, output: FrameOutput) -> None:
        for m in task.methods:
            if m.key not in output.rows:
                continue
            if m.key in output.previews:
                R.save_npz(R.preview_path(work, task.dataset_checksum, m.key), depth=output.previews[m.key],
                           method_key=np.array(m.key), frame=np.array(task.frame))
            part = R.cache_part(work, m.key, task.dataset_checksum, task.frame)
            part.parent.mkdir(parents=True, exist_ok=True)
            R.write_table(output.rows[m.key], part)
        bar.update(len(task.methods))

    try:
        if tasks:
            ex.run(tasks, on_done)
    finally:
        bar.close()

    # this run's rows, from the cache
    parts = [R.cache_part(work, m.key, ds.checksum, i) for m, ds, i in needed]
    new = R.read_parts([p for p in parts if p.exists()])
    _check_parts(new, needed, out)
    _check_references(new, ds_list)

    # earlier runs' rows that this run does not touch
    superseded: list[str] = []
    if prev_meta is not None and prev_meta.get("table"):
        old = R.load_results(work)
        pairs_new = set(zip(new["method"], new["dataset"]))
        touched = pd.Series([p in pairs_new for p in zip(old["method"], old["dataset"])], index=old.index, dtype=bool)
        old_pairs = old.loc[touched, ["method", "method_key", "dataset", "dataset_checksum"]].drop_duplicates()
        new_ids = set(zip(new["method_key"], new["dataset_checksum"]))
        superseded = sorted({f"{r.method_key} on {r.dataset}" for r in old_pairs.itertuples()
                             if (r.method_key, r.dataset_checksum) not in new_ids})
        table = pd.concat([old.loc[~touched], new], ignore_index=True)
    else:
        table = new
    table = R.sort_rows(table)
    digest = R.write_table(table, work / R.TABLE)
    _write_manifest(work, prev_meta, table, ds_list, method_list, config, digest, started, ex.name,
                    n_todo, reused, superseded)
    if superseded:
        log.debug("bench: superseded earlier rows of %s", "; ".join(superseded))
    return BenchResult(out, table, n_todo, reused, superseded)


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


def _write_manifest(work, prev_meta, table, ds_list, method_list, config, digest, started, executor, computed,
                    reused, superseded) -> None:
    prev = prev_meta or {}
    datasets = {d["checksum"]: d for d in prev.get("datasets", [])}
    for ds in ds_list:
        datasets[ds.checksum] = {"name": ds.name, "sequence": ds.sequence, "checksum": ds.checksum,
                                 "path": str(ds.root.resolve()), "frames": len(ds), "simulated": bool(ds.simulated),
                                 "preview_frame": preview_frame(ds)}
    present = set(table["dataset_checksum"].unique())
    methods = {m["key"]: m for m in prev.get("methods", [])}
    for m in method_list:
        methods[m.key] = {"name": m.name, "version": str(m.version), "key": m.key, "learned": bool(m.learned),
                          "description": getattr(m, "description", "") or ""}
    keys = set(table["method_key"].unique())
    try:
        from importlib.metadata import version
        db_version = version("depthbench")
    except Exception:   # noqa: BLE001 - not installed as a distribution
        db_version = "unknown"
    run = {"started": started, "finished": _now(), "executor": executor, "computed": int(computed),
           "reused": int(reused), "methods": [m.key for m in method_list],
           "datasets": [ds.name for ds in ds_list], "superseded": superseded}
    meta = {"format": R.FORMAT, "schema_version": R.SCHEMA_VERSION, "metrics": config.to_dict(),
            "table": {"file": R.TABLE, "sha256": digest, "rows": int(len(table))},
            "datasets": [d for c, d in datasets.items() if c in present],
            "methods": [m for k, m in methods.items() if k in keys],
            "runs": prev.get("runs", []) + [run], "depthbench_version": db_version}
    R.write_manifest(work, meta)
