#!/bin/bash
set -e
cd /work/wt/simtof
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
PY=/work/main/.venv/bin/python; S=/work/notes/simtof/scripts
$PY $S/sim_inv.py 0.98 capture simulate --rig lq-hq --scene people --seconds 2 --seed 0 --scale 0.5 --time-shift-ms 25 --out /tmp/simtof/inv/demo > /tmp/simtof/inv_sim.log 2>&1
for s in 1 2 4; do $PY $S/sim_inv.py 0.98 capture simulate --rig lq-hq --scene people --seconds 2 --seed $s --scale 0.5 --time-shift-ms 25 --frame-phase-ms 1 --out /tmp/simtof/inv/p$s >> /tmp/simtof/inv_sim.log 2>&1; done
for s in demo p1 p2 p4; do /work/main/.venv/bin/depthbench align /tmp/simtof/inv/$s --out /tmp/simtof/inv/al_base_$s --force --no-progress --no-report > /tmp/simtof/inv/al_$s.log 2>&1; done
cd $S; $PY hqsensor.py /tmp/simtof/inv/al_base_demo /tmp/simtof/inv/al_base_p1 /tmp/simtof/inv/al_base_p2 /tmp/simtof/inv/al_base_p4 > /tmp/simtof/hq_inv.txt 2>&1
echo done
