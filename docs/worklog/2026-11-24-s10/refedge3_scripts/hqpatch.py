"""hqpatch.py SESSION HQFRAME I J: HQ depth and truth 7x7 around (I, J)."""
import sys
import numpy as np
sys.path.insert(0, '/work/wt/refedge3')
from capture.session import open_session
from capture.truth import read_truth
s, fh, i, j = sys.argv[1], *map(int, sys.argv[2:5])
hq = open_session(s).read_depth('hq', fh); t = read_truth(s).depth('hq', fh)
np.set_printoptions(precision=2, linewidth=200, suppress=True)
print(hq[i-3:i+4, j-3:j+4]); print(t[i-3:i+4, j-3:j+4])
