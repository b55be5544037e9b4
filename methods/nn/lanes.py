"""Inference lanes: independent network passes side by side, each on its share of torch's CPU threads.

On a few CPU cores a narrow network gains little from running one pass on several threads: SSDD's
level 1 at width 8 takes about as long on two threads as on one, and every one of a pass's ~50
operations ends in a barrier of its threads, which is slow when other processes share the cores
(issue 10 worklog, session 11). Passes that do not depend on each other -- the k fold models
of ``ssdd_lstm``'s fold mean, the frames of an ``ssdd_unet`` batch -- then finish sooner side by
side: with ``n`` torch threads, ``min(n, jobs)`` Python threads ("lanes") with ``n // lanes``
intra-op threads each (``torch.set_num_threads`` is per thread). Each lane runs the same operations
on the same inputs as the one-thread-after-another path, so results agree with it to float
rounding (oneDNN may block a convolution differently for another thread count).

With one torch thread (the demo's workers, two to the two cores) there is one lane and everything
runs in the caller's thread, as before. ``DEPTHBENCH_LANES=0`` in the environment turns lanes off.
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterable, TypeVar

import torch

T = TypeVar("T")
R = TypeVar("R")

ENV = "DEPTHBENCH_LANES"


def enabled() -> bool:
    """False when the environment variable :data:`ENV` is ``0``, ``false``, ``no`` or ``off``."""
    return os.environ.get(ENV, "1").strip().lower() not in ("0", "false", "no", "off")


class Lanes:
    """:meth:`map` runs ``fn`` over items on ``lanes`` threads with ``threads`` torch threads each, in
    inference mode; with one lane, in the caller's thread (its own torch threads and grad mode)."""

    def __init__(self, lanes: int, threads: int) -> None:
        if lanes < 1 or threads < 1:
            raise ValueError(f"lanes and threads must be at least 1, got {lanes}, {threads}")
        self.lanes, self.threads = int(lanes), int(threads)
        self._pool: ThreadPoolExecutor | None = None
        self._pid = 0

    @classmethod
    def split(cls, jobs: int, *, device: str = "cpu") -> "Lanes":
        """Lanes for ``jobs`` independent passes on ``device``: torch's threads shared out on the CPU, one
        lane elsewhere or when lanes are off (:func:`enabled`)."""
        total = max(1, torch.get_num_threads())
        n = max(1, min(int(jobs), total)) if enabled() and device == "cpu" else 1
        return cls(n, total // n)

    def _executor(self) -> ThreadPoolExecutor:
        if self._pool is None or self._pid != os.getpid():   # a forked child has none of its parent's threads
            self._pool = ThreadPoolExecutor(self.lanes, thread_name_prefix="lane",
                                            initializer=torch.set_num_threads, initargs=(self.threads,))
            self._pid = os.getpid()
        return self._pool

    def map(self, fn: Callable[[T], R], items: Iterable[T]) -> list[R]:
        """``[fn(item) for item in items]``, the items side by side when there are several lanes."""
        items = list(items)
        if self.lanes == 1 or len(items) < 2:
            return [fn(item) for item in items]

        def run(item: T) -> R:
            with torch.inference_mode():
                return fn(item)

        return list(self._executor().map(run, items))

    def close(self) -> None:
        """Stop the lane threads (a later :meth:`map` starts them again)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
