#!/bin/bash
# align.sh TAG [extra align args]: align demo + p1 p2 p4 with the worktree's code into /tmp/refedge4/al_TAG_S
set -e
TAG=$1; shift
cd /work/wt/refedge4
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
DB=/work/main/.venv/bin/depthbench
for s in ${SESSIONS:-demo p1 p2 p4}; do
  $DB align /tmp/refedge4/$s --out /tmp/refedge4/al_${TAG}_$s --force --no-progress --no-report "$@" > /tmp/refedge4/al_${TAG}_$s.log 2>&1
done
