#!/bin/bash
# motion.sh on the code before the footprint HQ (371b651, extracted to /tmp/recheck/old, see ab_old.sh):
# the same sessions (seeds, phase) simulated point-sampled, scored by the same acc.py. bash motion_old.sh "1 2 3"
set -u
A=/work/wt/recheck/docs/worklog/2026-11-24-s12/recheck_scripts/acc.py
cd /tmp/recheck/old
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
PY=/work/main/.venv/bin/python; M=/tmp/recheck/m_old
for s in $1; do for p in 7 0; do
  [ -f $M/p${p}_s${s}/truth/truth.json ] || $PY -m depthbench capture simulate --out $M/p${p}_s${s} --scene people --seconds 2 --seed $s --frame-phase-ms $p --no-progress --force 2>&1 | head -1
  DUMP=$M/acc_p${p}_s${s}.json $PY $A $M/p${p}_s${s}
done; echo "$(date -u +%T) old seed $s done"; done
