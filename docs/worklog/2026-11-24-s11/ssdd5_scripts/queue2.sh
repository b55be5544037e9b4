#!/bin/bash
# held-out training seeds 30/40: baseline tiny (L) trained in full, A = level 2 retrained on L's level 1; benches on 201/206/207
R=/work/notes/ssdd5/run.sh
for s in 30 40; do echo "== train L$s"; bash $R train L $s; echo "== l2 A$s"; bash $R l2own A $s; done
for s in 30 40; do for S in 206 207 201; do
  d=/tmp/ssdd5/test$S; [ $S = 201 ] && d=/tmp/s4/test201
  echo "== A$s $S"; bash $R bench /tmp/ssdd5/A$s $d /tmp/ssdd5/R_A${s}_$S
  echo "== L$s $S"; bash $R bench /tmp/ssdd5/L$s $d /tmp/ssdd5/R_L${s}_$S
done; done
echo QUEUE2 DONE
