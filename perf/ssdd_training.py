"""SSDD training throughput with a config (default ``tiny``) on a training manifest.

    .venv/bin/python perf/ssdd_training.py --dataset CORPUS/training.json [--config tiny] [--method ssdd_lstm]

Trains into a temporary run folder through :func:`methods.nn.train.train_method` (what ``depthbench
methods train`` runs) and prints, per network, the training samples per second (median over epochs;
a level-2 sample is a sequence of ``sequence_length`` frames), the wall and CPU seconds of the whole
run, and the CPU/wall ratio (how many cores it kept busy). Make a corpus with ``depthbench bench corpus``.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from methods.nn.train import train_method  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", required=True, help="training manifest")
    ap.add_argument("--config", default="tiny")
    ap.add_argument("--method", default="ssdd_lstm")
    ap.add_argument("--device", default="cpu")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        wall, cpu = time.perf_counter(), time.process_time()
        res = train_method(a.method, dataset=a.dataset, config=a.config, out=Path(tmp) / "run", device=a.device,
                           progress=False)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    print(f"{a.method} with {a.config} on {a.device}: {wall:.1f} s wall, {cpu:.1f} s CPU ({cpu / wall:.2f} cores busy)")
    print(f"{'network':<22} {'samples/s':>10} {'epochs':>7}")
    for name, stage in res.stages.items():
        print(f"{name:<22} {stage['samples_per_s']:>10.1f} {stage['epochs']:>7}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
