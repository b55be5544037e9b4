#!/bin/bash
# ssdd4: issue 10 with an 8-training-sequence corpus (1001-1009, validation 1) vs the lead's 4-sequence one (/tmp/v10, 1001-1005)
# phase "sel": corpus, session 201, train seeds (arg list), bench 4-seq and 8-seq on 201
set -e
cd /work/wt/ssdd4; export PYTHONPATH=$PWD OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
D="/usr/bin/time -f CPU=%U+%S /work/main/.venv/bin/depthbench"
P=/work/main/.venv/bin/python
W=/tmp/s4; V=/tmp/v10
bench() { # model_dir session out
  $D bench run --data $W/test$2/aligned --methods raw,bilateral,ssdd_unet,ssdd_lstm --param ssdd_unet.weights=$1/ssdd_unet.safetensors \
    --param ssdd_lstm.weights=$1/ssdd_lstm.safetensors --jobs 1 --no-report --no-progress --out $3 --force 2>&1 | grep -v "^INFO" | tail -1
  echo "== $3"; $P perf/ssdd_paired.py $3/results.parquet --reference truth_roi --metric mse_moving_mm2 --pairs ssdd_lstm-ssdd_unet,ssdd_unet-bilateral
}
sim() {
  $D capture simulate --rig lq-hq --scene people --seconds 3 --seed $1 --scale 0.5 --time-shift-ms 25 --out $W/test$1/session --no-progress --force 2>&1 | tail -1
  $D align $W/test$1/session --out $W/test$1/aligned --force --no-progress --no-report 2>&1 | tail -1
}
train() { # seed
  sed -e "/^\[level1.optim\]/,/^\[/ s/^seed = 0/seed = $1/" -e "/^\[level2.optim\]/,\$ s/^seed = 1/seed = $(($1+1))/" methods/configs/ssdd/tiny.toml > $W/T_$1.toml
  cmp $W/T_$1.toml $V/T_$1.toml && echo "config same as v10's"
  echo "== train E$1"; $D methods train ssdd_lstm --dataset $W/corpus/training.json --config $W/T_$1.toml --out $W/E$1 --device cpu --no-progress --force 2>&1 | tail -2
}
case $1 in
corpus) echo "== corpus"; $D bench corpus --out $W/corpus --seeds 1001-1009 --seconds 1.2 --validation 1 --no-report --jobs 1 --no-progress --force 2>&1 | tail -2
        sim 201 ;;
sel) s=$2; train $s; bench $W/E$s 201 $W/R_E${s}_201; bench $V/L$s 201 $W/R_L${s}_201 ;;
fresh) for S in 204 205; do sim $S; done ;;
rep) s=$2; for S in 204 205; do bench $W/E$s $S $W/R_E${s}_$S; bench $V/L$s $S $W/R_L${s}_$S; done ;;
esac
echo "PHASE $* DONE"
