"""diffmask.py A B: pixels scored in B but not in A (A masks more): count, error distribution, share of B's squared error"""
import sys
import numpy as np
from common import frame_errors, per_frame, ratio
ea, _ = frame_errors(sys.argv[1]); eb, _ = frame_errors(sys.argv[2])
extra = np.isfinite(eb) & ~np.isfinite(ea)
a = np.abs(eb[extra])
print(f"extra scored {extra.sum()}: |e| >20 {np.sum(a>20)} >50 {np.sum(a>50)} >100 {np.sum(a>100)} >300 {np.sum(a>300)}; "
      f"sq-err share of B {np.sum(a*a)/np.nansum(eb*eb):.3f}")
fr = np.where(extra.any(axis=(1,2)))[0]
for lo, hi in ((20, 100), (100, 300), (300, 1e9)):
    sel = extra & (np.abs(eb) >= lo) & (np.abs(eb) < hi)
    print(f"  [{lo},{hi}) mm: {sel.sum()} px in {len(np.unique(np.where(sel)[0]))} frames, sq share {np.sum(eb[sel]**2)/np.nansum(eb*eb):.3f}")
