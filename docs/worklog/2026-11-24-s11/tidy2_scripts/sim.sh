#!/bin/bash
# tidy2: held-out sessions for the loop's pose covariance (the loopref recipe, fresh seeds)
cd /work/wt/tidy2
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 PYTHONPATH=$PWD
S="/work/main/.venv/bin/depthbench capture simulate --rig lq-hq --scene people --scale 0.5 --workers 1 --no-progress"
for s in "$@"; do
  $S --seconds 2 --seed $s --effect distortion_k1=0.1 --undeclared --out /tmp/tidy2/k1_$s >/dev/null 2>&1
  $S --seconds 2 --seed $s --effect rolling_shutter_ms=30 --undeclared --out /tmp/tidy2/rs_$s >/dev/null 2>&1
  $S --seconds 8 --seed $s --effect clock_drift_ppm=1000 --undeclared --out /tmp/tidy2/dr_$s >/dev/null 2>&1
  echo $s $(date +%T)
done
