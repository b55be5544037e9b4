#!/bin/bash
# tidy2: align one simulated session with two code trees (footprint-fg, motion edges and flow) and compare
# aligned.json's dataset_checksum. usage: same.sh TREE_BEFORE TREE_AFTER SESSION TAG
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
for tree in "$1" "$2"; do
  n=$(basename $tree)
  for mm in edges flow; do
    PYTHONPATH=$tree /work/main/.venv/bin/depthbench align $3 --out /tmp/tidy2/same_$4_${n}_$mm --force --no-progress --no-report --workers 1 --motion-model $mm > /dev/null 2>&1
    echo $n $mm $(/work/main/.venv/bin/python -c "import json; m=json.load(open('/tmp/tidy2/same_$4_${n}_$mm/aligned.json')); print(m['dataset_checksum'], m['reference_edges']['rule'], m['motion']['compensated'])")
  done
done
