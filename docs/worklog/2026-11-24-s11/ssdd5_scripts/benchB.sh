#!/bin/bash
# benchB.sh SESSION_DIR S SEEDS: ssdd_lstm of B$s (level1_input = "final") on a session -> /tmp/ssdd5/R_B${s}_$S
cd /work/wt/ssdd5; export PYTHONPATH=$PWD OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
for s in $3; do
/usr/bin/time -f "B$s $2 CPU=%U+%S" /work/main/.venv/bin/depthbench bench run --data $1/aligned --methods ssdd_lstm \
  --param ssdd_lstm.weights=/tmp/ssdd5/B$s/ssdd_lstm.safetensors --jobs 1 --no-report --no-progress --out /tmp/ssdd5/R_B${s}_$2 --force 2>&1 | grep -v "^INFO" | tail -1
done
