#!/bin/bash
# ssdd5: run.sh l2 TAG SEED   -> level 2 retrained (--resume) on a copy of /tmp/v10/L$SEED's level 1 with /tmp/ssdd5/${TAG}_$SEED.toml
#        run.sh bench RUN SESSION_DIR OUT -> bench run + paired LSTM-UNet, UNet-BF on moving pixels (truth_roi)
#        run.sh sim S   -> simulate + align held-out session S into /tmp/ssdd5/test$S
#        run.sh train TAG SEED -> full tiny training with /tmp/ssdd5/${TAG}_$SEED.toml into /tmp/ssdd5/${TAG}$SEED
set -e
cd /work/wt/ssdd5; export PYTHONPATH=$PWD OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
D="/usr/bin/time -f CPU=%U+%S /work/main/.venv/bin/depthbench"
P=/work/main/.venv/bin/python
W=/tmp/ssdd5; V=/tmp/v10
case $1 in
l2) tag=$2; s=$3; dst=$W/$tag$s; rm -rf $dst; mkdir -p $dst; cp -r $V/L$s/level1 $V/L$s/run.json $dst/
    $D methods train ssdd_lstm --dataset $V/corpus/training.json --config $W/${tag}_$s.toml --out $dst --device cpu --no-progress --resume 2>&1 | tail -1
    for f in final fold0 fold1; do cmp $V/L$s/level1/$f/checkpoint.safetensors $dst/level1/$f/checkpoint.safetensors; done
    cmp $V/L$s/ssdd_unet.safetensors $dst/ssdd_unet.safetensors && echo "level 1 identical" ;;
train) tag=$2; s=$3; $D methods train ssdd_lstm --dataset $V/corpus/training.json --config $W/${tag}_$s.toml --out $W/$tag$s --device cpu --no-progress --force 2>&1 | tail -1 ;;
bench) $D bench run --data $3/aligned --methods raw,bilateral,ssdd_unet,ssdd_lstm --param ssdd_unet.weights=$2/ssdd_unet.safetensors \
    --param ssdd_lstm.weights=$2/ssdd_lstm.safetensors --jobs 1 --no-report --no-progress --out $4 --force 2>&1 | grep -v "^INFO" | tail -1
    $P perf/ssdd_paired.py $4/results.parquet --reference truth_roi --metric mse_moving_mm2 --pairs ssdd_lstm-ssdd_unet,ssdd_unet-bilateral ;;
sim) S=$2; $D capture simulate --rig lq-hq --scene people --seconds 3 --seed $S --scale 0.5 --time-shift-ms 25 --out $W/test$S/session --no-progress --force 2>&1 | tail -1
     $D align $W/test$S/session --out $W/test$S/aligned --force --no-progress --no-report 2>&1 | tail -1 ;;
esac
case $1 in
l2own) tag=$2; s=$3; src=$W/L$s; dst=$W/$tag$s; rm -rf $dst; mkdir -p $dst; cp -r $src/level1 $src/run.json $dst/
    $D methods train ssdd_lstm --dataset $V/corpus/training.json --config $W/${tag}_$s.toml --out $dst --device cpu --no-progress --resume 2>&1 | tail -1 ;;
esac
