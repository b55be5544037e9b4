#!/bin/bash
# loopref: simulate sessions with undeclared effects and measure (measure.py)
cd /work/wt/loopref
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 PYTHONPATH=$PWD
S="/work/main/.venv/bin/depthbench capture simulate --rig lq-hq --scene people --scale 0.5 --workers 1 --no-progress"
M="/work/main/.venv/bin/python /work/notes/loopref/measure.py /work/notes/loopref/res.jsonl"
for s in 4002 4003 4004 4005; do
  $S --seconds 2 --seed $s --effect distortion_k1=0.1 --undeclared --out /tmp/loopref/k1_$s >/dev/null 2>&1
  $S --seconds 2 --seed $s --effect rolling_shutter_ms=30 --undeclared --out /tmp/loopref/rs_$s >/dev/null 2>&1
  $S --seconds 2 --seed $s --out /tmp/loopref/clean_$s >/dev/null 2>&1
  $M /tmp/loopref/k1_$s /tmp/loopref/rs_$s /tmp/loopref/clean_$s > /dev/null 2>&1
done
$S --seconds 2 --seed 4002 --effect depth_scale=1.03 --undeclared --out /tmp/loopref/ds_4002 >/dev/null 2>&1
$M /tmp/loopref/ds_4002 >/dev/null 2>&1
for s in 4001 4002 4003 4004; do
  $S --seconds 8 --seed $s --effect clock_drift_ppm=1000 --undeclared --out /tmp/loopref/dr_$s >/dev/null 2>&1
  $M /tmp/loopref/dr_$s >/dev/null 2>&1
done
echo done
