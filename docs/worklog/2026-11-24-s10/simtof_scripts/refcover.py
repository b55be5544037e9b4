"""coverage.py DIR...: ROI pixels, ROI pixels with a reference, and the share of the ROI without one (truth_noref's share)."""
import sys
import numpy as np
sys.path.insert(0, '/work/wt/simtof')
from align.dataset import AlignedDataset
for d in sys.argv[1:]:
    ds = AlignedDataset(d)
    roi = ref = 0
    for i in range(len(ds)):
        r, m = ds.reference(i), ds.roi(i)
        roi += int(m.sum()); ref += int((m & np.isfinite(r)).sum())
    print(f"{d}: ROI {roi}, with reference {ref}, without {100 * (roi - ref) / roi:.2f} %")
