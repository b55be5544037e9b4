#!/bin/bash
# sim2.sh N TAG SEEDS: simulate with TofNoise.footprint_samples = N (via the sensor profile default patched) and align (full band 3 and 2)
set -e
N=$1; TAG=$2; shift 2
cd /work/wt/footprint
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
PY=/work/main/.venv/bin/python
for s in "$@"; do
  if [ $s = 0 ]; then extra=""; else extra="--frame-phase-ms 1"; fi
  $PY -c "
import sys, dataclasses
import capture.sim.noise as N
f = {x.name: x for x in dataclasses.fields(N.TofNoise)}
N.TofNoise.__dataclass_fields__['footprint_samples'].default = $N
N.TofNoise.__init__.__defaults__  # noqa
import capture.sim.noise
orig = N.TofNoise.__init__
def init(self, *a, **k):
    k.setdefault('footprint_samples', $N); orig(self, *a, **k)
N.TofNoise.__init__ = init
from depthbench.cli import main
sys.exit(main(sys.argv[1:]))
" capture simulate --rig lq-hq --scene people --seconds 2 --seed $s --scale 0.5 --time-shift-ms 25 $extra --out /tmp/fp/${TAG}_s$s --force --no-progress > /tmp/fp/${TAG}_s$s.simlog 2>&1
  $PY -c "import json;print(json.load(open('/tmp/fp/${TAG}_s$s/session.json'))['sensors']['hq']['noise']['footprint_samples'])"
  /work/main/.venv/bin/depthbench align /tmp/fp/${TAG}_s$s --out /tmp/fp/al_${TAG}_s$s --force --no-progress --no-report > /dev/null 2>&1 &
  $PY /work/notes/fp/align_band.py 2 align /tmp/fp/${TAG}_s$s --out /tmp/fp/al_${TAG}b2_s$s --force --no-progress --no-report > /dev/null 2>&1
  wait
done
