"""tidy2: bench.diagnose.stats.edge_errors on a simulated session's HQ sensor against its truth depth (every 6th
frame), with the code on PYTHONPATH: edge band pixels per frame and the flying / fattened fractions.
usage: edgecount.py SESSION"""
import sys
from pathlib import Path
import numpy as np
import cv2
from bench.diagnose.stats import edge_errors
root = Path(sys.argv[1])
tr = sorted((root / "truth/hq/depth").iterdir())[::6]
me = sorted((root / "hq/depth").iterdir())[::6]
out = []
for t, m in zip(tr, me):
    zt = cv2.imread(str(t), cv2.IMREAD_UNCHANGED).astype(np.float32)
    zm = cv2.imread(str(m), cv2.IMREAD_UNCHANGED).astype(np.float32)
    zt = np.where(zt > 0, zt * 1e-4, np.nan).astype(np.float32)
    zm = np.where(zm > 0, zm * 1e-3, np.nan).astype(np.float32)
    out.append(edge_errors(zm, zt))
px = [e.pixels for e in out]
print(f"frames {len(out)} band px/frame {np.mean(px):.0f} of {zt.size}; flying {np.mean([e.flying_fraction for e in out]):.3f} "
      f"fattened {np.mean([e.fattened_fraction for e in out]):.3f} missing {np.mean([e.missing_fraction for e in out]):.3f}")
