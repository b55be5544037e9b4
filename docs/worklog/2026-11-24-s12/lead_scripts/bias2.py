"""bias2.py ALIGNED UNET_WEIGHTS: the -2cov(UNet) + 2cov(RGF) term by |ref - truth| bin (mm), all scored pixels"""
import sys
import numpy as np
sys.path.insert(0, '/work/wt/footprint')
from align.dataset import AlignedDataset
from methods.registry import get
ds = AlignedDataset(sys.argv[1])
unet = get('ssdd_unet', weights=sys.argv[2]); rgf = get('rolling_guidance')
bins = [0, 5, 10, 20, 50, 100, 300, 1e9]
acc = np.zeros((len(bins) - 1, 3))
for i in range(len(ds)):
    f = ds.frame(i)
    r, t = f.reference.astype(np.float64), f.truth.astype(np.float64)
    pu = unet.denoise(f.lq_depth, f.lq_color, camera=ds.lq_intrinsics).astype(np.float64)
    pr = rgf.denoise(f.lq_depth, f.lq_color, camera=ds.lq_intrinsics).astype(np.float64)
    m = f.roi & np.isfinite(r) & np.isfinite(t) & np.isfinite(pu) & np.isfinite(pr)
    n = m.sum()
    er = (r - t) * 1000
    for b in range(len(bins) - 1):
        q = m & (np.abs(er) >= bins[b]) & (np.abs(er) < bins[b + 1])
        acc[b, 0] += -2 * np.sum(((pu - t) * 1000 * er)[q]) / n / len(ds)
        acc[b, 1] += -2 * np.sum(((pr - t) * 1000 * er)[q]) / n / len(ds)
        acc[b, 2] += q.sum() / n / len(ds)
for b in range(len(bins) - 1):
    print(f"|r-t| [{bins[b]:g},{bins[b+1]:g}) mm: share {acc[b,2]*100:6.3f} % | UNet {acc[b,0]:7.2f} | RGF {acc[b,1]:7.2f} | diff {acc[b,0]-acc[b,1]:+6.2f}")
