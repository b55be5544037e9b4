#!/bin/bash
# A perf/loop_study.py run on the code of one commit (its simulator too), extracted to /tmp/recheck/at_<commit>
# (git archive, no worktree), own cache. bash at_commit.sh COMMIT TAG ARGS...   (run from the worktree root)
set -u
c=$1; tag=$2; shift 2
d=/tmp/recheck/at_$c
[ -d $d ] || { mkdir -p $d && git archive $c | tar -x -C $d; }
cd $d
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
/work/main/.venv/bin/python perf/loop_study.py --simulated --cache /tmp/recheck/cache_$c --jsonl /tmp/recheck/rows/$tag.jsonl "$@" > /tmp/recheck/rows/$tag.log 2>&1
echo "$(date -u +%T) done $tag" >> /tmp/recheck/rows/chain.log
