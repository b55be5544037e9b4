#!/bin/bash
# Issue 12 motion item on the footprint HQ simulator (session 12, recheck): the sessions of
# 2026-11-24-s10/motion3_scripts/sim.sh (people, 2 s, full scale, frame phase 7 ms and its synchronous twin 0 ms),
# then acc.py (the s10 scorer: perf/reference_motion.py's flow column, 10 pairs, strict edges) on each.
# Run from the worktree root: bash docs/worklog/2026-11-24-s12/recheck_scripts/motion.sh "1 2 3 ..."
set -u
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
PY=/work/main/.venv/bin/python; M=/tmp/recheck/m; D=docs/worklog/2026-11-24-s12/recheck_scripts
for s in $1; do for p in 7 0; do
  [ -f $M/p${p}_s${s}/truth/truth.json ] || $PY -m depthbench capture simulate --out $M/p${p}_s${s} --scene people --seconds 2 --seed $s --frame-phase-ms $p --no-progress --force 2>&1 | head -1
  DUMP=$M/acc_p${p}_s${s}.json $PY $D/acc.py $M/p${p}_s${s}
done; echo "$(date -u +%T) seed $s done"; done
