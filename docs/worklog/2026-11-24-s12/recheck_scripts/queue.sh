#!/bin/bash
# the order the recheck runs went in (one job at a time): large.sh (started by hand after the clean 20), then this.
D=docs/worklog/2026-11-24-s12/recheck_scripts
bash $D/large2.sh
bash $D/motion.sh "1 2 3 4 5 6"
bash $D/small.sh
bash $D/motion.sh "7 8 9 10 11 12 13 14 15 16 17 18"
