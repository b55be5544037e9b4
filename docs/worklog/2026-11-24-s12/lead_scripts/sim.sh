#!/bin/bash
# sim.sh FP TAG SEEDS: simulate demo (seed 0) / held-out seeds with the footprint ToF (FP sub-samples per axis; 0 = off)
set -e
FPN=$1; TAG=$2; shift 2
cd /work/wt/footprint
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
[ "$FPN" != 0 ] && export FP=$FPN
DB=/work/main/.venv/bin/depthbench
for s in "$@"; do
  if [ $s = 0 ]; then extra=""; else extra="--frame-phase-ms 1"; fi
  $DB capture simulate --rig lq-hq --scene people --seconds 2 --seed $s --scale 0.5 --time-shift-ms 25 $extra --out /tmp/fp/${TAG}_s$s --force --no-progress > /tmp/fp/${TAG}_s$s.simlog 2>&1
  $DB align /tmp/fp/${TAG}_s$s --out /tmp/fp/al_${TAG}_s$s --force --no-progress --no-report > /tmp/fp/al_${TAG}_s$s.log 2>&1
done
