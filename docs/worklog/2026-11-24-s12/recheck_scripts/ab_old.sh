#!/bin/bash
# The same studies on the code before the footprint HQ (371b651, the parent of 6b630b4: point-sampled HQ, band 3 px),
# extracted with `git archive 371b651 | tar -x -C /tmp/recheck/old`, own cache: what the footprint changes, paired
# by seed, everything else equal. Run from anywhere: bash ab_old.sh
set -u
cd /tmp/recheck/old
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
R=/tmp/recheck/rows; C=/tmp/recheck/cache_old; PY=/work/main/.venv/bin/python
study() { tag=$1; shift; $PY perf/loop_study.py --simulated --cache $C --jsonl $R/$tag.jsonl "$@" >> $R/$tag.log 2>&1; echo "$(date -u +%T) done $tag" >> $R/chain.log; }
study old_small_lqk1 --seconds 4 --seeds 21-26 --effect distortion_k1=0.02
