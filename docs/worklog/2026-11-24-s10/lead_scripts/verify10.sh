#!/bin/bash
# issue 10's ordering re-measured on main as it stands (after simtof's coverage flying-pixel default):
# corpus, held-out 202/203, tiny (offset=level1) training seeds 0/10/20, bench, paired LSTM - UNet on moving pixels
set -e
cd /work/wt/verify; export PYTHONPATH=$PWD OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
D="/usr/bin/time -f %U+%S /work/main/.venv/bin/depthbench"
W=/tmp/v10; mkdir -p $W
$D bench corpus --out $W/corpus --seeds 1001-1005 --seconds 1.2 --validation 1 --no-report --jobs 1 --no-progress --force
for s in 0 10 20; do
  sed -e "/^\[level1.optim\]/,/^\[/ s/^seed = 0/seed = $s/" -e "/^\[level2.optim\]/,\$ s/^seed = 1/seed = $((s+1))/" methods/configs/ssdd/tiny.toml > $W/T_$s.toml
done
for s in 202 203; do
  $D capture simulate --rig lq-hq --scene people --seconds 3 --seed $s --scale 0.5 --time-shift-ms 25 --out $W/test$s/session --no-progress --force
  $D align $W/test$s/session --out $W/test$s/aligned --force --no-progress --no-report
done
for s in 0 10 20; do
  $D methods train ssdd_lstm --dataset $W/corpus/training.json --config $W/T_$s.toml --out $W/L$s --device cpu --no-progress --force
  for S in 202 203; do
    $D bench run --data $W/test$S/aligned --methods raw,bilateral,ssdd_unet,ssdd_lstm --param ssdd_unet.weights=$W/L$s/ssdd_unet.safetensors \
      --param ssdd_lstm.weights=$W/L$s/ssdd_lstm.safetensors --jobs 1 --no-report --no-progress --out $W/R_${s}_$S --force 2>&1 | grep -v "^INFO" | tail -1
    /work/main/.venv/bin/python perf/ssdd_paired.py $W/R_${s}_$S/results.parquet --reference truth_roi --metric mse_moving_mm2 --pairs ssdd_lstm-ssdd_unet,ssdd_unet-bilateral
  done
done
echo VERIFY DONE
