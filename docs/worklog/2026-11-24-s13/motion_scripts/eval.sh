#!/bin/bash
# Session 13 motion: score every seed with this checkout (strict: acc.py; footprint-fg: acc_rule.py ROI=rule), and main on
# the fresh seeds 25-36 under footprint-fg. One job, single-threaded.
set -u
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
PY=/work/main/.venv/bin/python; M=/tmp/recheck/m; O=/tmp/motion; D=docs/worklog/2026-11-24-s12/recheck_scripts
cd /work/wt/motion
for s in $(seq 1 36); do for p in 7 0; do
  DUMP=$O/s13_acc_p${p}_s${s}.json PYTHONPATH=$PWD $PY $D/acc.py $M/p${p}_s${s}
done; done
for s in $(seq 1 36); do for p in 7 0; do
  ROI=rule RULE=footprint-fg DUMP=$O/s13_fg_p${p}_s${s}.json PYTHONPATH=$PWD $PY $D/acc_rule.py $M/p${p}_s${s}
done; done
cd /work/main
for s in $(seq 25 36); do for p in 7 0; do
  ROI=rule RULE=footprint-fg DUMP=$O/main_fg_p${p}_s${s}.json PYTHONPATH=$PWD $PY $D/acc_rule.py $M/p${p}_s${s}
done; done
echo "$(date -u +%T) eval done"
