#!/bin/bash
# What the width costs (issue 10): tiny's recipe at seed 0 with both nets at the network default (width 16, 4 levels)
# against tiny (width 8, 3 levels; the lead's /tmp/v10/L0, same corpus and seed), scored on held-out 202/203 vs truth.
# Corpus, test sessions and T_0.toml from docs/worklog/2026-11-24-s10/lead_scripts/verify10.sh.
set -e
cd /work/wt/infer2; export PYTHONPATH=$PWD OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1
D="/usr/bin/time -f %e_s_%U+%S_cpu /work/main/.venv/bin/depthbench"
V=/tmp/v10; W=/tmp/infer2/w
sed -e 's/^width = 8/width = 16/' -e 's/^levels = 3/levels = 4/' $V/T_0.toml > $W/W16_0.toml
$D methods train ssdd_lstm --dataset $V/corpus/training.json --config $W/W16_0.toml --out $W/L16 --device cpu --no-progress --force
for S in 202 203; do
  for m in 8 16; do
    run=$([ $m = 8 ] && echo $V/L0 || echo $W/L16)
    $D bench run --data $V/test$S/aligned --methods raw,bilateral,ssdd_unet,ssdd_lstm --param ssdd_unet.weights=$run/ssdd_unet.safetensors \
      --param ssdd_lstm.weights=$run/ssdd_lstm.safetensors --jobs 1 --no-report --no-progress --out $W/R${m}_$S --force 2>&1 | grep -v "^INFO" | tail -1
  done
done
echo WIDTH DONE
