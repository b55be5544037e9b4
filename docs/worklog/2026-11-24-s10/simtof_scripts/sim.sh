#!/bin/bash
# simulate the demo session (seed 0) and held-out seeds 1/2/4 (frames ~1 ms apart), as refedge.md
set -e
cd /work/wt/simtof
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
DB=/work/main/.venv/bin/depthbench
$DB capture simulate --rig lq-hq --scene people --seconds 2 --seed 0 --scale 0.5 --time-shift-ms 25 --out /tmp/simtof/demo
for s in 1 2 4; do
  $DB capture simulate --rig lq-hq --scene people --seconds 2 --seed $s --scale 0.5 --time-shift-ms 25 --frame-phase-ms 1 --out /tmp/simtof/p$s
done
