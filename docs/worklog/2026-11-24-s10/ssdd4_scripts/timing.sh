#!/bin/bash
# same-run CPU comparison: tiny seed 0 on the 4-seq corpus (/tmp/v10) then on the 8-seq corpus (/tmp/s4), twice alternating
cd /work/wt/ssdd4; export PYTHONPATH=$PWD OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
D="/usr/bin/time -f CPU=%U+%S /work/main/.venv/bin/depthbench"
for rep in 1 2; do for c in v10 s4; do
  echo "== $c rep $rep"; $D methods train ssdd_lstm --dataset /tmp/$c/corpus/training.json --config /tmp/s4/T_0.toml --out /tmp/s4/TT_${c}_$rep --device cpu --no-progress --force 2>&1 | tail -1
done; done
/work/main/.venv/bin/python - <<'PY'
from safetensors.torch import load_file
import torch
for a, b in [("/tmp/v10/L0", "/tmp/s4/TT_v10_1"), ("/tmp/s4/E0", "/tmp/s4/TT_s4_1")]:
    for m in ("ssdd_unet", "ssdd_lstm"):
        x, y = load_file(f"{a}/{m}.safetensors"), load_file(f"{b}/{m}.safetensors")
        print(a, b, m, all(torch.equal(x[k], y[k]) for k in x) and x.keys() == y.keys())
PY
echo TIMING DONE
