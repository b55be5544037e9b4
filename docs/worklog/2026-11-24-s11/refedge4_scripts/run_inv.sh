#!/bin/bash
# Azure-like invalidation (simtof's sim_inv.py, flying_invalid_fraction F over 0.2 m jumps) on demo + seeds,
# aligned with footprint-fg and footprint-mixed-fg. usage: run_inv.sh F "SEEDS"
set -e
F=$1; SEEDS=${2:-"0 1 2 4"}
cd /work/wt/refedge4
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
PY=/work/main/.venv/bin/python; S=/work/notes/refedge4; O=/tmp/refedge4/inv$F; mkdir -p $O
for s in $SEEDS; do
  if [ $s = 0 ]; then n=demo; a="--seed 0"; else n=p$s; a="--seed $s --frame-phase-ms 1"; fi
  $PY $S/sim_inv.py $F capture simulate --rig lq-hq --scene people --seconds 2 --scale 0.5 --time-shift-ms 25 $a --out $O/$n > $O/sim_$n.log 2>&1
  for r in footprint-fg footprint-mixed-fg; do
    /work/main/.venv/bin/depthbench align $O/$n --out $O/al_${r}_$n --force --no-progress --no-report --reference-edges $r > $O/al_${r}_$n.log 2>&1
  done
done
echo done
