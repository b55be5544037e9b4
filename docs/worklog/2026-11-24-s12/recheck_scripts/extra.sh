#!/bin/bash
# Issue 12, the rest of the loop's Must-show rows on the footprint HQ simulator (session 12, recheck):
# drift 1000 ppm over 4 s (not met before: the 8 s row is the large size), two effects at once (s6 rows).
set -u
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
R=/tmp/recheck/rows; C=/tmp/recheck/cache; PY=/work/main/.venv/bin/python
study() { tag=$1; shift; $PY perf/loop_study.py --simulated --cache $C --jsonl $R/$tag.jsonl "$@" >> $R/$tag.log 2>&1; echo "$(date -u +%T) done $tag" >> $R/chain.log; }
study two_scale_rs --seconds 4 --seeds 11-12 --effect depth_scale=1.03 --effect rolling_shutter_ms=30
study two_drift_lqk1 --seconds 8 --seeds 11-12 --effect clock_drift_ppm=1000 --effect distortion_k1=0.1
study drift4 --seconds 4 --seeds 11-12 --effect clock_drift_ppm=1000
