"""kneed.py TAG...: the oracle's k (fewest truth-chosen pixels, largest |error| first, that bring the ratio to <= 2),
the budget B left under 2 % (aligned.json's share), and the precision a rule would need in its top B (k / B) against
the base rate of those pixels among the scored ones (> 0.3 m pixels / scored): the enrichment any witness must reach."""
import sys
import numpy as np
from common import frame_errors, per_frame, ratio
sys.path.insert(0, '/work/wt/refedge4')
from align.dataset import AlignedDataset

for t in sys.argv[1:]:
    root = t if t.startswith('/') else f'/tmp/refedge4/al_base_{t}'
    e, share = frame_errors(root); tot = AlignedDataset(root).meta['reference_edges']['roi_pixels']
    a = np.abs(e).ravel(); order = np.argsort(-np.nan_to_num(a, nan=-1))
    k = 0
    while True:
        e2 = e.copy().ravel(); e2[order[:k]] = np.nan
        if ratio(*per_frame(e2.reshape(e.shape))) <= 2.0 or k > 500:
            break
        k += 1
    B = int((0.02 - share) * tot); sc = int(np.isfinite(e).sum()); big = int(np.sum(a > 300))
    print(f"{t}: k {k} (the k-th |error| {a[order[k-1]] if k else 0:.0f} mm), budget {B} px, needed precision {k / max(B, 1):.2%}, "
          f"base rate {big / sc:.5%} (> 0.3 m), needed enrichment {k / max(B, 1) / (big / sc):.0f}x")
