#!/bin/bash
# lead s11: variant C = A (tiny as on main) with [level1.optim] samples_per_epoch 400 -> 800 (level 1 twice the steps)
# c11.sh train S ; c11.sh bench TAG S SESSION
set -e
cd /work/main; export PYTHONPATH=$PWD OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
D="/usr/bin/time -f CPU=%U+%S /work/main/.venv/bin/depthbench"
P=/work/main/.venv/bin/python; W=/tmp/lead11; V=/tmp/v10; X=/tmp/ssdd5
case $1 in
train) s=$2
  sed -e "/^\[level1.optim\]/,/^\[/ s/^seed = 0/seed = $s/" -e "/^\[level1.optim\]/,/^\[/ s/^samples_per_epoch = 400/samples_per_epoch = 800/" \
      -e "/^\[level2.optim\]/,\$ s/^seed = 1/seed = $((s+1))/" methods/configs/ssdd/tiny.toml > $W/C_$s.toml
  $D methods train ssdd_lstm --dataset $V/corpus/training.json --config $W/C_$s.toml --out $W/C$s --device cpu --no-progress --force 2>&1 | tail -1 ;;
bench) tag=$2; s=$3; S=$4; if [ $tag = C ]; then R=$W/C$s; else R=$X/A$s; fi
  $D bench run --data $X/test$S/aligned --methods raw,bilateral,ssdd_unet,ssdd_lstm --param ssdd_unet.weights=$R/ssdd_unet.safetensors \
    --param ssdd_lstm.weights=$R/ssdd_lstm.safetensors --jobs 1 --no-report --no-progress --out $W/R_${tag}${s}_$S --force 2>&1 | grep -v "^INFO" | tail -1
  echo "== $tag seed $s session $S"
  $P perf/ssdd_paired.py $W/R_${tag}${s}_$S/results.parquet --reference truth_roi --metric mse_moving_mm2 --pairs ssdd_lstm-ssdd_unet,ssdd_unet-bilateral ;;
esac
