#!/bin/bash
# footprint-fg with a MASK_PX-wide band on demo p1 p2 p4 -> /tmp/refedge4/al_band$MASK_PX_S
set -e
cd /work/wt/refedge4
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
for s in ${SESSIONS:-demo p1 p2 p4}; do
  /work/main/.venv/bin/python /work/notes/refedge4/align_band.py $1 align /tmp/refedge4/$s --out /tmp/refedge4/al_band$1_$s --force --no-progress --no-report > /tmp/refedge4/al_band$1_$s.log 2>&1
done
