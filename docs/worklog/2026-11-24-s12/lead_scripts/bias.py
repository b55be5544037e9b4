"""bias.py ALIGNED UNET_WEIGHTS: where does the reference favour SSDD UNet over RGF relative to the truth?
MSE_ref(m) - MSE_truth(m) = mean[(r-t)^2] - 2 mean[(m-t)(r-t)] on the scored pixels (ROI, reference valid, both valid);
the method-dependent part is -2 mean[(m-t)(r-t)]. Prints, per stratum, the share of the UNet-RGF difference of that term
(mm^2, summed per frame / n scored per frame, averaged over frames)."""
import sys
import numpy as np, cv2
sys.path.insert(0, '/work/wt/footprint')
from align.dataset import AlignedDataset
from bench.metrics import pixel_errors
from methods.registry import get
from bench.masks import truth_strata, valid_mask
ds = AlignedDataset(sys.argv[1])
unet = get('ssdd_unet', weights=sys.argv[2]) if True else None
rgf = get('rolling_guidance')
strata = ['edge<=1', 'edge 2-3', 'edge 4-6', 'far']
acc = {s: [0.0, 0.0, 0] for s in strata}  # cov term unet, rgf, n
tot_n = 0
for i in range(len(ds)):
    f = ds.frame(i)
    r, t = f.reference.astype(np.float64), f.truth.astype(np.float64)
    pu = unet.denoise(f.lq_depth, f.lq_color, camera=ds.lq_intrinsics).astype(np.float64)
    pr = rgf.denoise(f.lq_depth, f.lq_color, camera=ds.lq_intrinsics).astype(np.float64)
    m = f.roi & np.isfinite(r) & np.isfinite(t) & np.isfinite(pu) & np.isfinite(pr)
    # distance to a truth depth edge (3 % jump in a 3x3)
    tt = np.where(np.isfinite(t), t, 0).astype(np.float32)
    k = np.ones((3, 3), np.uint8)
    edge = (cv2.dilate(tt, k) - cv2.erode(tt, k)) > 0.03 * np.maximum(tt, 0.1)
    dist = cv2.distanceTransform((~edge).astype(np.uint8), cv2.DIST_L2, 3)
    n = m.sum(); tot_n += n
    for s, sel in zip(strata, (dist <= 1.5, (dist > 1.5) & (dist <= 3.5), (dist > 3.5) & (dist <= 6.5), dist > 6.5)):
        q = m & sel
        er = (r - t)[q] * 1000
        acc[s][0] += -2 * np.sum((pu - t)[q] * 1000 * er) / n / len(ds)
        acc[s][1] += -2 * np.sum((pr - t)[q] * 1000 * er) / n / len(ds)
        acc[s][2] += q.sum()
print("stratum: share of scored px | -2cov(UNet) | -2cov(RGF) | difference UNet-RGF (mm^2, per-frame mean)")
for s in strata:
    a = acc[s]
    print(f"{s:10s} {a[2]/tot_n:6.3f} | {a[0]:7.2f} | {a[1]:7.2f} | {a[0]-a[1]:+7.2f}")
print("total diff", sum(a[0] - a[1] for a in acc.values()))
