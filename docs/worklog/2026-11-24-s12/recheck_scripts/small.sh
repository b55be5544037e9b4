#!/bin/bash
# Issue 12, small sizes, undeclared, on the footprint HQ simulator (session 12): the s6 rows' configurations and seeds.
# Run from the worktree root: bash docs/worklog/2026-11-24-s12/recheck_scripts/small.sh
set -u
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
R=/tmp/recheck/rows; C=/tmp/recheck/cache; PY=/work/main/.venv/bin/python
study() { tag=$1; shift; $PY perf/loop_study.py --simulated --cache $C --jsonl $R/$tag.jsonl "$@" >> $R/$tag.log 2>&1; echo "$(date -u +%T) done $tag" >> $R/chain.log; }
study small_offset --seconds 4 --seeds 21-26 --effect depth_offset_mm=10
study small_scale  --seconds 4 --seeds 21-23 --effect depth_scale=1.003
study small_lqk1   --seconds 4 --seeds 21-26 --effect distortion_k1=0.02
# added after the first three (run at 08:45): the other two small rows of session 6
study small_rs8    --seconds 4 --seeds 21-23 --effect rolling_shutter_ms=8
study small_hqk1   --seconds 4 --seeds 21-25 --effect hq_distortion_k1=0.02
study small_rs8b   --seconds 4 --seeds 24-29 --effect rolling_shutter_ms=8
