#!/bin/bash
# same-run SSDD training CPU: tiny before (level 2 at 240 steps) and after (960), alternating, on the demo-recipe corpus
cd /work/wt/ssdd5; export PYTHONPATH=$PWD OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
for rep in 1 2; do for c in before after; do
  echo "== $c rep $rep"; /usr/bin/time -f "CPU=%U+%S wall=%e" /work/main/.venv/bin/python perf/ssdd_training.py --dataset /tmp/v10/corpus/training.json --config /tmp/ssdd5/tiny_$c.toml 2>&1 | grep -v "^INFO"
done; done
echo TIMING DONE
