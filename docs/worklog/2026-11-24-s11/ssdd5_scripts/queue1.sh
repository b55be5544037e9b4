#!/bin/bash
# fresh sessions 206/207 (after the decision), then A and L benches on them
R=/work/notes/ssdd5/run.sh
for S in 206 207; do echo "== sim $S"; bash $R sim $S; done
for S in 206 207; do for s in 0 10 20; do
  echo "== A$s $S"; bash $R bench /tmp/ssdd5/A$s /tmp/ssdd5/test$S /tmp/ssdd5/R_A${s}_$S
  echo "== L$s $S"; bash $R bench /tmp/v10/L$s /tmp/ssdd5/test$S /tmp/ssdd5/R_L${s}_$S
done; done
echo QUEUE1 DONE
