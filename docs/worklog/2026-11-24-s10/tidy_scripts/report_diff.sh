#!/bin/bash
# Byte-identical check: write the leaderboard of one results folder with the code at $1 (before) and $2 (after).
set -e
SRC=$3
for side in before after; do
  code=$1; [ $side = after ] && code=$2
  rm -rf /tmp/tidy_rep_$side; mkdir -p /tmp/tidy_rep_$side
  cp -r $SRC/results.parquet $SRC/results.json $SRC/previews /tmp/tidy_rep_$side/
  (cd $code && PYTHONPATH=$code /work/main/.venv/bin/python -c "import sys, bench.report as r; print(r.__file__); r.write_report(sys.argv[1])" /tmp/tidy_rep_$side)
done
diff -r /tmp/tidy_rep_before /tmp/tidy_rep_after && echo IDENTICAL
(cd /tmp/tidy_rep_after && sha256sum leaderboard.md leaderboard.html figures/*)
