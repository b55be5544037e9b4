"""Rendering worker processes, started as ``python -m capture.sim.worker``.

Why not ``multiprocessing``: its ``spawn`` start method re-imports the caller's main module
(which breaks scripts without a ``__main__`` guard, notebooks and ``python -``), and ``fork``
after Open3D's and numba's thread pools exist can deadlock. A plain subprocess has neither
problem. The protocol on the worker's stdin/stdout is length-prefixed pickles: the parent sends
the :class:`~capture.sim.output.Plan`, then events; the worker answers each event, in order,
with ``("ok", EncodedFrame)`` or ``("error", exception)``; ``None`` ends it.
"""
from __future__ import annotations

import os
import pickle
import signal
import struct
import subprocess
import sys
from pathlib import Path
from typing import BinaryIO, Iterator

from capture.sim.errors import SimulationError

_HEADER = struct.Struct("<Q")
#: Events handed to one worker ahead of the one the parent waits for.
IN_FLIGHT = 3


def send(stream: BinaryIO, obj) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_HEADER.pack(len(data)))
    stream.write(data)
    stream.flush()


def receive(stream: BinaryIO):
    head = stream.read(_HEADER.size)
    if len(head) < _HEADER.size:
        raise EOFError
    (n,) = _HEADER.unpack(head)
    data = stream.read(n)
    if len(data) < n:
        raise EOFError
    return pickle.loads(data)


class WorkerPool:
    """``n`` worker processes rendering events round robin; :meth:`map` yields results in order."""

    def __init__(self, plan, n: int) -> None:
        root = str(Path(__file__).resolve().parents[2])  # the folder holding the capture package
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
        self.procs = [subprocess.Popen([sys.executable, "-m", "capture.sim.worker"], stdin=subprocess.PIPE,
                                       stdout=subprocess.PIPE, env=env) for _ in range(n)]
        for p in self.procs:
            send(p.stdin, plan)

    def map(self, events: list) -> Iterator:
        n = len(self.procs)
        sent = 0

        def feed(upto: int) -> None:
            nonlocal sent
            while sent < min(upto, len(events)):
                send(self.procs[sent % n].stdin, events[sent])
                sent += 1

        feed(n * IN_FLIGHT)
        for j in range(len(events)):
            proc = self.procs[j % n]
            try:
                status, payload = receive(proc.stdout)
            except EOFError:
                raise SimulationError(f"a rendering process stopped (exit status {proc.wait()})") from None
            if status == "error":
                raise payload
            feed(j + 1 + n * IN_FLIGHT)
            yield payload

    def close(self) -> None:
        for p in self.procs:
            try:
                send(p.stdin, None)
                p.stdin.close()
            except OSError:
                pass
        for p in self.procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()

    def kill(self) -> None:
        for p in self.procs:
            p.kill()
        for p in self.procs:
            p.wait()


def main() -> None:
    """Worker side: read the plan, then render events until ``None``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and ends us
    from capture.sim.pipeline import FrameWorker

    stdin, stdout = sys.stdin.buffer, sys.stdout.buffer
    sys.stdout = sys.stderr  # nothing else may write into the result pipe
    plan = receive(stdin)
    worker = FrameWorker(plan, nthreads=1)
    while True:
        try:
            event = receive(stdin)
        except EOFError:
            return
        if event is None:
            return
        try:
            send(stdout, ("ok", worker.render(event)))
        except Exception as exc:  # hand it to the parent, which raises it
            send(stdout, ("error", exc))


if __name__ == "__main__":
    main()
