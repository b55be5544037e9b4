#!/bin/bash
# tidy2: the feature fits' distance to the depth-refined rig, in their own (now cluster-robust + shift) sds
cd /work/wt/tidy2
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 PYTHONPATH=$PWD
for s in "$@"; do
  /work/main/.venv/bin/depthbench capture simulate --rig multiview4 --scale 0.5 --seconds 1 --seed $s --workers 1 --no-progress --out /tmp/tidy2/mv$s > /dev/null 2>&1
  /work/main/.venv/bin/depthbench align /tmp/tidy2/mv$s --out /tmp/tidy2/mva$s --probes 8 --allow-unobservable --no-progress --workers 1 > /tmp/tidy2/mva$s.log 2>&1
  echo $s $(date +%T) rc=$?
done
