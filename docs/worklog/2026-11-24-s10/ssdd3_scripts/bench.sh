#!/bin/bash
# bench.sh RUN SESSION METHODS: bench run of METHODS (ssdd weights from /tmp/s3/RUN) on held-out session SESSION -> /tmp/s3/R_RUN_SESSION
set -e
cd /work/wt/ssdd3; export PYTHONPATH=$PWD OMP_NUM_THREADS=1
W=/tmp/s3; r=$1; s=$2; m=${3:-raw,bilateral,ssdd_unet,ssdd_lstm}
/usr/bin/time -f "bench $r $s %U+%S" /work/main/.venv/bin/depthbench bench run --data $W/test$s/aligned --methods $m \
  $([[ $m == *ssdd_unet* ]] && echo --param ssdd_unet.weights=$W/$r/ssdd_unet.safetensors) --param ssdd_lstm.weights=$W/$r/ssdd_lstm.safetensors \
  --jobs 1 --no-report --no-progress --out $W/R_${r}_$s --force 2>&1 | grep -v "^INFO" | tail -1
