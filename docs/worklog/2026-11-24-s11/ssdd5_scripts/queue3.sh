#!/bin/bash
# fresh sessions 208/209 (after rule B's decision): A (full methods) and B (ssdd_lstm only), five seeds; then L
R=/work/notes/ssdd5/run.sh
for S in 208 209; do echo "== sim $S"; bash $R sim $S; done
for S in 208 209; do for s in 0 10 20 30 40; do echo "== A$s $S"; bash $R bench /tmp/ssdd5/A$s /tmp/ssdd5/test$S /tmp/ssdd5/R_A${s}_$S; done
  bash /work/notes/ssdd5/benchB.sh /tmp/ssdd5/test$S $S "0 10 20 30 40"; done
echo "== A B DONE"
for S in 208 209; do for s in 0 10 20 30 40; do m=/tmp/v10/L$s; [ -d $m ] || m=/tmp/ssdd5/L$s
  echo "== L$s $S"; bash $R bench $m /tmp/ssdd5/test$S /tmp/ssdd5/R_L${s}_$S; done; done
echo QUEUE3 DONE
