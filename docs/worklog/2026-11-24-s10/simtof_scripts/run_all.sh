#!/bin/bash
set -e
cd /work/notes/simtof/scripts
bash sim.sh > /tmp/simtof/sim.log 2>&1
bash align.sh base
PYTHONPATH=/work/wt/simtof /work/main/.venv/bin/python hqsensor.py /tmp/simtof/al_base_demo /tmp/simtof/al_base_p1 /tmp/simtof/al_base_p2 /tmp/simtof/al_base_p4 > /tmp/simtof/hq_cov.txt 2>&1
echo done
