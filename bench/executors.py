"""Where benchmark tasks run: in this process, a local process pool, or Dask (a local or remote cluster).

An executor runs a task function (:func:`bench.compute.compute_frame` by default; the training
corpus builder passes its own, :mod:`bench.corpus`) on every task and hands each output to a
callback as soon as it arrives; the tasks and their outputs do not depend on which executor ran
them. The function must be importable by name (module-level) for worker processes. :class:`ExecutorSpec` is the user's choice, checked before anything is read or written.
"""
from __future__ import annotations

import logging
import multiprocessing
import os
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass

from bench import results as R
from bench.compute import compute_frame
from bench.errors import BenchError

EXECUTORS = ("process", "dask")


def _share(processes: int) -> int:
    """CPU threads each of ``processes`` local worker processes may use."""
    return max(1, (os.cpu_count() or 1) // max(1, processes))


class _Serial:
    name = "serial"
    threads = _share(1)

    def run(self, tasks, on_done, *, fn=compute_frame, key=None):
        for t in tasks:
            on_done(t, fn(t))


class _Processes:
    def __init__(self, jobs: int) -> None:
        self.jobs = jobs
        self.name = f"process x{jobs}"
        self.threads = _share(jobs)

    def run(self, tasks, on_done, *, fn=compute_frame, key=None):
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload([fn.__module__])
        ex = ProcessPoolExecutor(max_workers=self.jobs, mp_context=ctx)
        try:
            pending = {ex.submit(fn, t): t for t in tasks}
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

    def run(self, tasks, on_done, *, fn=compute_frame, key=None):
        """``key(task)``: the Dask key of a task (default: the benchmark's frame-task key)."""
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
            futures = {client.submit(fn, t, key=(key or _frame_key)(t), pure=False): t for t in tasks}
            try:
                for f in as_completed(list(futures)):
                    on_done(futures[f], f.result())
            finally:
                client.cancel(list(futures))
        finally:
            client.close()
            if cluster is not None:
                cluster.close()


def _frame_key(t) -> str:
    return f"bench-{t.dataset_checksum[:16]}-{t.frames[0]:06d}-{R.short('|'.join(m.key for m in t.methods))}"


@dataclass(frozen=True)
class ExecutorSpec:
    """Where to run: ``executor`` ``"process"`` (``jobs`` local processes; default the CPU count, 1 =
    this process) or ``"dask"`` (``workers`` processes of a ``LocalCluster``, or the cluster at
    ``scheduler``); ``workers`` or ``scheduler`` imply Dask."""

    executor: str = "process"
    jobs: int | None = None
    workers: int | None = None
    scheduler: str | None = None

    def check(self) -> "ExecutorSpec":
        """Raise :class:`BenchError` for impossible choices (before anything is read or written)."""
        if self.executor not in EXECUTORS:
            raise BenchError(f"executor must be one of {', '.join(EXECUTORS)}, got {self.executor!r}")
        for name, value in (("--workers", self.workers), ("--jobs", self.jobs)):
            if value is not None and value < 1:
                raise BenchError(f"{name} must be at least 1, got {value}")
        if self.workers is not None and self.scheduler is not None:
            raise BenchError("give --workers (a local Dask cluster) or --scheduler (an existing one), not both")
        return self

    def make(self, n_tasks: int):
        """The executor for ``n_tasks`` tasks (a local pool never has more processes than tasks)."""
        self.check()
        if self.executor == "dask" or self.workers is not None or self.scheduler is not None:
            return _Dask(self.workers or os.cpu_count() or 1, self.scheduler)
        jobs = min(self.jobs or os.cpu_count() or 1, max(n_tasks, 1))
        return _Serial() if jobs <= 1 else _Processes(jobs)


# ----------------------------------------------------------------------------------- the run
