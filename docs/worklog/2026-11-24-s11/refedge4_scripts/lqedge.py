"""lqedge.py DATASET: the LQ colour image alone as a silhouette witness (no truth in the score). For a scored pixel p
on the near side of a reference silhouette (photo.silhouette_dist 0): a_in = min RGB distance from c(p) to its
8-neighbours that the reference puts on p's surface (finite, within 10 %); a_out = min to its 8-neighbours that are
reference holes or > 10 % farther. score = a_in - a_out (p looks like the other side). Masks score >= t; prints,
per t, the masked share, > 0.3 m pixels caught and the ratio."""
import sys
import numpy as np
from common import frame_errors, per_frame, ratio
from photo import silhouette_dist
sys.path.insert(0, '/work/wt/refedge4')
from align.dataset import AlignedDataset

root = sys.argv[1]
e, share = frame_errors(root); ds = AlignedDataset(root); tot = ds.meta['reference_edges']['roi_pixels']
S = np.full(e.shape, np.nan)
for f in range(len(ds)):
    ref = ds.reference(f); c = ds.lq_color(f).astype(np.float32)
    H, W = ref.shape
    zp = np.pad(ref, 1, constant_values=np.nan); cp = np.pad(c, ((1, 1), (1, 1), (0, 0)))
    a_in = np.full((H, W), np.inf); a_out = np.full((H, W), np.inf)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di == dj == 0:
                continue
            zn = zp[1 + di:1 + di + H, 1 + dj:1 + dj + W]; cn = cp[1 + di:1 + di + H, 1 + dj:1 + dj + W]
            d = np.linalg.norm(cn - c, axis=2)
            with np.errstate(invalid='ignore'):
                same = np.abs(zn - ref) <= 0.1 * ref
                other = ~np.isfinite(zn) | (zn > 1.1 * ref)
            a_in = np.where(same, np.minimum(a_in, d), a_in); a_out = np.where(other, np.minimum(a_out, d), a_out)
    cand = np.isfinite(e[f]) & (silhouette_dist(ref) <= 0) & np.isfinite(a_out)
    S[f] = np.where(cand, np.where(np.isfinite(a_in), a_in, 442.0) - a_out, np.nan)
big = np.abs(np.nan_to_num(e)) > 300
print(f"{root}: budget to 2 %: {int((0.02 - share) * tot)} px; big scores: {np.round(S[big], 0)}")
for t in (0, 10, 20, 40, 80):
    m = S >= t
    mae, rmse = per_frame(np.where(m, np.nan, e))
    print(f"  score>={t}: +{100*m.sum()/tot:.2f} % ({m.sum()} px), caught {np.sum(m & big)}/{big.sum()}, ratio {ratio(mae, rmse):.2f}")
