#!/bin/bash
# Issue 12, large sizes, undeclared, on the footprint HQ simulator (session 12). One job at a time, single-threaded.
# Run from the worktree root: bash docs/worklog/2026-11-24-s12/recheck_scripts/large.sh
set -u
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
R=/tmp/recheck/rows; C=/tmp/recheck/cache; PY=/work/main/.venv/bin/python
study() { tag=$1; shift; $PY perf/loop_study.py --simulated --cache $C --jsonl $R/$tag.jsonl "$@" >> $R/$tag.log 2>&1; echo "$(date -u +%T) done $tag" >> $R/chain.log; }
study clean4   --seconds 4 --seeds 11-12
study lqk1     --seconds 4 --seeds 11-12 --effect distortion_k1=0.1
study scale    --seconds 4 --seeds 11-12 --effect depth_scale=1.03
study offset   --seconds 4 --seeds 11-12 --effect depth_offset_mm=50
study rs30     --seconds 4 --seeds 11-12 --effect rolling_shutter_ms=30
study hqk1     --seconds 4 --seeds 11-12 --effect hq_distortion_k1=0.1
study dup      --seconds 4 --seeds 11-12 --effect frame_duplicate_rate=0.1
study drop     --seconds 4 --seeds 11-12 --effect frame_drop_rate=0.1
study clean8   --seconds 8 --seeds 11-12
study drift8   --seconds 8 --seeds 11-12 --effect clock_drift_ppm=1000
