#!/bin/bash
# simulate the demo session (seed 0) and held-out seeds (frames ~1 ms apart), as refedge3's sim.sh
set -e
cd /work/wt/refedge4
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
DB=/work/main/.venv/bin/depthbench
for s in ${SEEDS:-0 1 2 4}; do
  if [ $s = 0 ]; then
    $DB capture simulate --rig lq-hq --scene people --seconds 2 --seed 0 --scale 0.5 --time-shift-ms 25 --out /tmp/refedge4/demo
  else
    $DB capture simulate --rig lq-hq --scene people --seconds 2 --seed $s --scale 0.5 --time-shift-ms 25 --frame-phase-ms 1 --out /tmp/refedge4/p$s
  fi
done
