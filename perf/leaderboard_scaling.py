"""Timing: the leaderboard of the demo data on a Dask LocalCluster of 2 workers against 1.

    .venv/bin/python perf/leaderboard_scaling.py [--data ALIGNED] [--seconds 3] [--methods all]

Without ``--data`` the demo's data is made first, through the same commands the demo runs
(``depthbench capture simulate --rig lq-hq --scene people --seconds 3 --seed 0`` and
``depthbench align``), in a temporary folder. Then ``bench.runner.run_benchmark`` scores every
method on every frame three times into fresh results folders (nothing cached): Dask with 1 worker,
Dask with 2 workers, and the default local process pool; each time includes starting the
cluster and writing the table and the leaderboard. The tables must be identical; the script
prints the wall times, the 1-worker / 2-worker ratio and the machine's load average (timings on a
shared machine are upper bounds).
"""
from __future__ import annotations

import argparse
import hashlib
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.runner import run_benchmark  # noqa: E402


def _cpu() -> float:
    """CPU seconds of this process and its finished children (Dask and pool workers are children)."""
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def make_demo_data(root: Path, seconds: float) -> Path:
    session, aligned = root / "session", root / "aligned"
    for argv in (["capture", "simulate", "--rig", "lq-hq", "--scene", "people", "--seconds", f"{seconds:g}",
                  "--seed", "0", "--out", str(session), "--no-progress"],
                 ["align", str(session), "--out", str(aligned)]):
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "depthbench", *argv], capture_output=True, text=True)
        if proc.returncode != 0:
            sys.exit(f"demo data: 'depthbench {' '.join(argv)}' failed: {proc.stderr.strip().splitlines()[-1:]}")
        print(f"  depthbench {argv[0]} {argv[1]}: {time.perf_counter() - t0:.0f} s")
    return aligned


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, help="an aligned dataset (default: make the demo's)")
    ap.add_argument("--seconds", type=float, default=3.0, help="simulated seconds when making the demo data")
    ap.add_argument("--methods", default="all")
    ap.add_argument("--threads-per-task", type=int, default=None,
                    help="CPU threads per task (default: the CPUs shared among the workers: 2 for 1 worker, "
                         "1 each for 2 workers on 2 CPUs)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="depthbench-scaling-") as tmp:
        tmp = Path(tmp)
        if args.data is None:
            print(f"making the demo data ({args.seconds:g} s simulated) ...")
            args.data = make_demo_data(tmp, args.seconds)
        runs = {}
        for label, kw in (("dask, 1 worker", {"workers": 1}), ("dask, 2 workers", {"workers": 2}),
                          ("local processes", {})):
            load = os.getloadavg()[0]
            c0 = _cpu()
            t0 = time.perf_counter()
            res = run_benchmark([args.data], args.methods, tmp / label.replace(" ", "_").replace(",", ""),
                                threads_per_task=args.threads_per_task, **kw)
            dt = time.perf_counter() - t0
            cpu = _cpu() - c0
            digest = hashlib.sha256(res.table_path.read_bytes()).hexdigest()
            runs[label] = (dt, digest, res.computed, load)
            print(f"  {label:<16} {dt:7.1f} s wall, {cpu:7.1f} s CPU ({cpu / dt:.2f} cores busy) for {res.computed} "
                  f"results ({dt / res.computed * 1e3:.0f} ms each); load average before: {load:.1f}")
        t1, t2 = runs["dask, 1 worker"][0], runs["dask, 2 workers"][0]
        same = len({d for _, d, _, _ in runs.values()}) == 1
        print(f"\n2 workers vs 1: {t1 / t2:.2f}x faster (ideal 2.00x on {os.cpu_count()} CPUs); "
              f"tables {'identical' if same else 'DIFFER'} (sha256 of results.parquet)")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
