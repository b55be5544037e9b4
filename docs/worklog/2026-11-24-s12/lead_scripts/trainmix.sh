#!/bin/bash
# corpus with the footprint-mixed-fg references (training only), SSDD tiny on it, bench on the demo's aligned (default rule)
set -e
cd /work/wt/footprint
export PYTHONPATH=$PWD
DB=/work/main/.venv/bin/depthbench
$DB bench corpus --scale 0.5 --jobs 1 --no-report --out /tmp/fp/corpus_mix --seeds 1001,1002,1003,1004,1005 --seconds 1.2 --validation 1 --force --reference-edges footprint-mixed-fg --no-progress
$DB methods train ssdd_lstm --dataset /tmp/fp/corpus_mix/training.json --config tiny --out /tmp/fp/runs_mix --force --no-progress
R=/tmp/fp/runs_mix
$DB bench run --data /tmp/fp/demo/aligned --methods raw,bilateral,rolling_guidance,ssdd_unet,ssdd_lstm --param ssdd_unet.weights=$R/ssdd_unet.safetensors --param ssdd_lstm.weights=$R/ssdd_lstm.safetensors --out /tmp/fp/bench_mixtrain --radius-mm 10 --jobs 1 --force --no-progress
