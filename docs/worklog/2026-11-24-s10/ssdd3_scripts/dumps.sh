#!/bin/bash
# dumps.sh RUNNAME SESSIONS... : dump.py for the validation sequence and the sessions
cd /work/wt/ssdd3; export PYTHONPATH=$PWD OMP_NUM_THREADS=1
P=/work/main/.venv/bin/python; W=/tmp/s3; r=$1; shift
$P /work/notes/ssdd3/dump.py $W/$r $W/corpus/aligned/people-seed1005 $W/d_${r}_val.npz
for s in "$@"; do $P /work/notes/ssdd3/dump.py $W/$r $W/test$s/aligned $W/d_${r}_$s.npz; done
