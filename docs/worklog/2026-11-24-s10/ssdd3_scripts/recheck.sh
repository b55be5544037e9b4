#!/bin/bash
# recheck.sh: tiny as landed (offset = "level1") on main after the ToF flying-pixel change (3d107ac): corpus, 202/203, seeds 0/10/20
cd /work/wt/ssdd3; export PYTHONPATH=$PWD OMP_NUM_THREADS=1
D="/usr/bin/time -f %U+%S /work/main/.venv/bin/depthbench"
W=/tmp/s3n; mkdir -p $W
$D bench corpus --out $W/corpus --seeds 1001-1005 --seconds 1.2 --validation 1 --no-report --jobs 1 --no-progress 2>&1 | tail -1
for s in 202 203; do
  $D capture simulate --rig lq-hq --scene people --seconds 3 --seed $s --scale 0.5 --time-shift-ms 25 --out $W/test$s/session --no-progress --force 2>&1 | tail -1
  $D align $W/test$s/session --out $W/test$s/aligned --force --no-progress --no-report 2>&1 | tail -1
done
for s in 0 10 20; do
  sed -e "/^\[level1.optim\]/,/^\[/ s/^seed = 0/seed = $s/" -e "/^\[level2.optim\]/,\$ s/^seed = 1/seed = $((s+1))/" methods/configs/ssdd/tiny.toml > $W/N_$s.toml
  $D methods train ssdd_lstm --dataset $W/corpus/training.json --config $W/N_$s.toml --out $W/N$s --device cpu --no-progress --force 2>&1 | tail -1
  for t in 202 203; do
    $D bench run --data $W/test$t/aligned --methods raw,bilateral,ssdd_unet,ssdd_lstm --param ssdd_unet.weights=$W/N$s/ssdd_unet.safetensors --param ssdd_lstm.weights=$W/N$s/ssdd_lstm.safetensors --jobs 1 --no-report --no-progress --out $W/R_N${s}_$t --force 2>&1 | grep -v ^INFO | tail -1
    /work/main/.venv/bin/python perf/ssdd_paired.py $W/R_N${s}_$t/results.parquet --reference truth_roi --metric mse_moving_mm2 --pairs ssdd_lstm-ssdd_unet
  done
done
echo RECHECK DONE
