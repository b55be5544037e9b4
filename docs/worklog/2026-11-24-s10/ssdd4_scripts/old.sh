#!/bin/bash
# the 8-seq models on the lead's 202/203 (/tmp/v10/test20{2,3}; already looked at, extra evidence only)
cd /work/wt/ssdd4; export PYTHONPATH=$PWD OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
for s in 0 10 20; do for S in 202 203; do
  /work/main/.venv/bin/depthbench bench run --data /tmp/v10/test$S/aligned --methods raw,bilateral,ssdd_unet,ssdd_lstm --param ssdd_unet.weights=/tmp/s4/E$s/ssdd_unet.safetensors \
    --param ssdd_lstm.weights=/tmp/s4/E$s/ssdd_lstm.safetensors --jobs 1 --no-report --no-progress --out /tmp/s4/R_E${s}_$S --force 2>&1 | grep -v "^INFO" | tail -1
  mkdir -p /tmp/s4/R_L${s}_$S; ln -sf /tmp/v10/R_${s}_$S/results.parquet /tmp/s4/R_L${s}_$S/results.parquet
done; done
for S in 202 203; do /work/main/.venv/bin/python /work/notes/ssdd4/cross.py $S 0 10 20; done
echo OLD DONE
