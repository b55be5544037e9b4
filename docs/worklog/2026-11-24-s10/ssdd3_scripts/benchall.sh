#!/bin/bash
for s in 201 202 203; do for seed in 0 10 20; do
  /work/notes/ssdd3/bench.sh L$seed $s raw,bilateral,ssdd_unet,ssdd_lstm
  /work/notes/ssdd3/bench.sh O$seed $s ssdd_lstm
done; done; echo BENCH DONE
