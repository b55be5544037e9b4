#!/bin/bash
# l2only.sh SRC DST CONFIG: level 2 retrained (--resume) on a copy of SRC's level 1 (fold + final checkpoints, unchanged)
set -e
cd /work/wt/ssdd3; export PYTHONPATH=$PWD OMP_NUM_THREADS=1
W=/tmp/s3; src=$W/$1; dst=$W/$2; cfg=$3
rm -rf $dst; mkdir -p $dst; cp -r $src/level1 $src/run.json $dst/
/usr/bin/time -f %U+%S /work/main/.venv/bin/depthbench methods train ssdd_lstm --dataset $W/corpus/training.json --config $cfg --out $dst --device cpu --no-progress --resume
