#!/bin/bash
# Issue 12, large sizes, seeds 13-14, undeclared, on the footprint HQ simulator (session 12). One job at a time, single-threaded.
# Run from the worktree root: bash docs/worklog/2026-11-24-s12/recheck_scripts/large2.sh
set -u
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
R=/tmp/recheck/rows; C=/tmp/recheck/cache; PY=/work/main/.venv/bin/python
study() { tag=$1; shift; $PY perf/loop_study.py --simulated --cache $C --jsonl $R/$tag.jsonl "$@" >> $R/$tag.log 2>&1; echo "$(date -u +%T) done $tag" >> $R/chain.log; }
study clean4_b   --seconds 4 --seeds 13-14
study lqk1_b     --seconds 4 --seeds 13-14 --effect distortion_k1=0.1
study scale_b    --seconds 4 --seeds 13-14 --effect depth_scale=1.03
study offset_b   --seconds 4 --seeds 13-14 --effect depth_offset_mm=50
study rs30_b     --seconds 4 --seeds 13-14 --effect rolling_shutter_ms=30
study hqk1_b     --seconds 4 --seeds 13-14 --effect hq_distortion_k1=0.1
study dup_b      --seconds 4 --seeds 13-14 --effect frame_duplicate_rate=0.1
study drop_b     --seconds 4 --seeds 13-14 --effect frame_drop_rate=0.1
study clean8_b   --seconds 8 --seeds 13-14
study drift8_b   --seconds 8 --seeds 13-14 --effect clock_drift_ppm=1000
