"""side.py DIR: for reference pixels with |err| in bins, where is the nearer surface (within 3 px): left/right/up/down;
and the cost of a band by side: pixels in the far side band with the near surface to the left vs right."""
import sys
import numpy as np, cv2
from common import frame_errors
from align.dataset import AlignedDataset
from bench.masks import truth_strata, valid_mask
root = sys.argv[1]
ds = AlignedDataset(root)
stats = {}
for i in range(len(ds)):
    ref = ds.reference(i); tru = ds.truth(i); roi = ds.roi(i)
    t = truth_strata(tru, ref)['truth']; m = valid_mask(ref, t, roi)
    e = np.abs(ref.astype(np.float64) - t) * 1000
    z = np.where(np.isfinite(ref), ref, np.inf).astype(np.float32)
    H, W = z.shape
    sides = {}
    for name, (dx, dy) in dict(L=(-1, 0), R=(1, 0), U=(0, -1), D=(0, 1)).items():
        near = np.zeros((H, W), bool)
        for k in (1, 2, 3):
            sh = np.full((H, W), np.inf, np.float32)
            ys = slice(max(0, -dy * k), H - max(0, dy * k)); yd = slice(max(0, dy * k), H - max(0, -dy * k))
            xs = slice(max(0, -dx * k), W - max(0, dx * k)); xd = slice(max(0, dx * k), W - max(0, -dx * k))
            # value at p + k*(dx,dy)
            sh[ys, xs] = z[yd, xd]
            with np.errstate(invalid='ignore'):
                near |= (z - sh > 0.03 * sh)
        sides[name] = near & m
    for b, (lo, hi) in enumerate(((0, 20), (20, 100), (100, 300), (300, 1e9))):
        sel = (e >= lo) & (e < hi) & m
        for name, s in sides.items():
            c = stats.setdefault((lo, name), [0, 0, 0.0])
            c[0] += int(np.sum(sel & s)); c[1] += int(np.sum(sel)); c[2] += float(np.sum((e * e)[sel & s]))
for (lo, name), (n, N, se) in sorted(stats.items()):
    print(f"err>={lo:5} mm, nearer surface {name}: {n:7d} of {N:8d}  sq-err {se/1e6:9.2f} m2*1e-6")
