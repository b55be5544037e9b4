#!/bin/bash
# A/B of the throughput: perf/reference_motion.py SESSION --frames 2 --speed-frames 30, alternating checkouts.
# ab.sh N SESSION DIR_A DIR_B   (prints the flow CPU ratio and edges CPU ratio of each run)
N=$1; S=$2; shift 2
for r in $(seq 1 $N); do for d in "$@"; do
  line=$(cd $d && OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 PYTHONPATH=$d /work/main/.venv/bin/python perf/reference_motion.py $S --frames 2 --speed-frames 30 2>/dev/null | grep -E "^  (flow|edges)" | sed -E 's/.*CPU time plain ([0-9.]+), (flow|edges) ([0-9.]+), ratio ([0-9.]+)/\2 plain \1 \2 \3 ratio \4/' | tr '\n' ' ')
  echo "$(date +%T) $d: $line"
done; done
