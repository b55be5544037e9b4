#!/bin/bash
set -e
cd /work/main; export PYTHONPATH=$PWD OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
D="/usr/bin/time -f CPU=%U+%S /work/main/.venv/bin/depthbench"; S=$1; W=/tmp/ssdd5
$D capture simulate --rig lq-hq --scene people --seconds 3 --seed $S --scale 0.5 --time-shift-ms 25 --out $W/test$S/session --no-progress --force 2>&1 | tail -1
$D align $W/test$S/session --out $W/test$S/aligned --force --no-progress --no-report 2>&1 | tail -1
