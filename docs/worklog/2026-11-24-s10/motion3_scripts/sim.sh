#!/bin/bash
# simulate the motion sessions: seeds 1-18, frame phase 7 ms and synchronous twin (0 ms)
cd /work/wt/motion3
for s in $(seq 1 18); do for p in 7 0; do
  [ -f /tmp/m3/p${p}_s${s}/truth/truth.json ] && continue
  PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 /work/main/.venv/bin/python -m depthbench capture simulate --out /tmp/m3/p${p}_s${s} --scene people --seconds 2 --seed $s --frame-phase-ms $p --no-progress --force 2>&1 | head -1
done; done
