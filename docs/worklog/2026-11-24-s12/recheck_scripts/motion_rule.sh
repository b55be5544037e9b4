#!/bin/bash
# acc_rule.py (ROI=rule, RULE=footprint-fg, motion model flow, as align builds references) on the motion sessions:
# bash motion_rule.sh CHECKOUT SESSIONS_DIR TAG "SEEDS"   e.g. /work/wt/recheck /tmp/recheck/m new "1 2 3"
set -u
A=/work/wt/recheck/docs/worklog/2026-11-24-s12/recheck_scripts/acc_rule.py
cd $1
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 ROI=rule RULE=footprint-fg
for s in $4; do for p in 7 0; do
  DUMP=/tmp/recheck/fg_$3_p${p}_s${s}.json /work/main/.venv/bin/python $A $2/p${p}_s${s}
done; done
