#!/bin/bash
# corpus on current main + held-out sessions 201/202/203 + landed-tiny training seeds 0/10/20
set -e
cd /work/wt/ssdd3; export PYTHONPATH=$PWD OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
D="/usr/bin/time -f %U+%S /work/main/.venv/bin/depthbench"
W=/tmp/s3
$D bench corpus --out $W/corpus --seeds 1001-1005 --seconds 1.2 --validation 1 --no-report --jobs 1 --no-progress
for s in 0 10 20; do
  sed -e "/^\[level1.optim\]/,/^\[/ s/^seed = 0/seed = $s/" -e "/^\[level2.optim\]/,\$ s/^seed = 1/seed = $((s+1))/" methods/configs/ssdd/tiny.toml > $W/T_$s.toml
done
for s in 201 202 203; do
  $D capture simulate --rig lq-hq --scene people --seconds 3 --seed $s --scale 0.5 --time-shift-ms 25 --out $W/test$s/session --no-progress --force
  $D align $W/test$s/session --out $W/test$s/aligned --force --no-progress --no-report
done
for s in 0 10 20; do
  $D methods train ssdd_lstm --dataset $W/corpus/training.json --config $W/T_$s.toml --out $W/L$s --device cpu --no-progress --force
done
echo PREP DONE
