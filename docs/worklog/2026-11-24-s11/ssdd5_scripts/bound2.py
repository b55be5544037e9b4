"""bound2.py DUMP.npz TRUEFLOW.npz ALIGNED: two-frame fusion of level 1 with a *realistic* part: the point's depth
change between frames estimated from the predictions (local median over a window of pred_t - carried pred_{t-1}),
with the true correspondence or with DIS colour flow (methods/ssdd/motion.py, kind = "color"); fuse only where the
two agree within GATE. Moving / all pixels MSE (mm^2) against level 1 alone, per-frame bootstrap."""
import sys
import numpy as np
from scipy.ndimage import generic_filter, median_filter
from align.dataset import AlignedDataset
from methods.ssdd.motion import MotionConfig, FlowSource

d = np.load(sys.argv[1]); f = np.load(sys.argv[2]); ds = AlignedDataset(sys.argv[3])
tr = d["truth"].astype(np.float64); lq = d["lq"]
n, H, W = tr.shape
M = d["roi"] & np.isfinite(lq) & (lq > 0) & np.isfinite(tr) & (tr > 0)
src = FlowSource(MotionConfig(kind="color"))
cols = [ds.lq_color(i) for i in range(n)]
rng = np.random.default_rng(0)
yy, xx = np.mgrid[0:H, 0:W]

def sample(img, u, v):
    ok = np.isfinite(u) & np.isfinite(v) & (u >= -0.5) & (u < W - 0.5) & (v >= -0.5) & (v < H - 0.5)
    ui = np.clip(np.rint(np.nan_to_num(u)), 0, W - 1).astype(int); vi = np.clip(np.rint(np.nan_to_num(v)), 0, H - 1).astype(int)
    return np.where(ok, img[vi, ui], np.nan)

MEDIAN = len(sys.argv) > 4 and sys.argv[4] == "median"
PREDS = ("final", "fm") if MEDIAN else ("final",)

def nanmedian_win(x, size):
    """median (argv[4] = median; slow) or mean (default) over the window of the finite values"""
    if MEDIAN:
        return generic_filter(x, np.nanmedian, size=size, mode="nearest")
    from scipy.ndimage import uniform_filter
    ok = np.isfinite(x)
    num = uniform_filter(np.where(ok, x, 0.0), size, mode="nearest"); den = uniform_filter(ok.astype(float), size, mode="nearest")
    return np.where(den > 0.5 / size ** 2, num / np.maximum(den, 1e-12), np.nan)

def fuse(pred, t, u, v, size, gate):
    p1 = sample(pred[t - 1], u, v)
    dz = pred[t] - p1
    dz_hat = nanmedian_win(np.where(M[t], dz, np.nan), size)
    c = p1 + dz_hat
    ok = np.isfinite(c) & (np.abs(c - pred[t]) < gate)
    return np.where(ok, 0.5 * (pred[t] + c), pred[t])

for name in PREDS:
    pred = d[name].astype(np.float64)
    out = {k: [] for k in ("L1", "true_dz", "dis_dz", "dis_nodz")}
    for t in range(1, n):
        mv = M[t] & M[t - 1] & (np.abs(tr[t] - tr[t - 1]) > 0.01)
        fl = src(cols[t], cols[t - 1])
        ut, vt = f["uv"][t, 0, ..., 0].astype(np.float64), f["uv"][t, 0, ..., 1].astype(np.float64)
        ud, vd = xx + fl[0], yy + fl[1]
        res = {"L1": pred[t],
               "true_dz": fuse(pred, t, ut, vt, 9, 0.03),
               "dis_dz": fuse(pred, t, ud, vd, 9, 0.03),
               "dis_nodz": np.where(np.abs(sample(pred[t - 1], ud, vd) - pred[t]) < 0.03,
                                    0.5 * (pred[t] + sample(pred[t - 1], ud, vd)), pred[t])}
        for k, r in res.items():
            e = r - tr[t]
            out[k].append([np.mean(e[mv] ** 2), np.mean(e[M[t]] ** 2)])
    base = np.array(out["L1"]) * 1e6
    print(f"== {name} (window 9, gate 3 cm, depth change by window {'median' if MEDIAN else 'mean'})")
    for k, v in out.items():
        a = np.array(v) * 1e6; dd = a - base
        bs = np.array([dd[rng.integers(0, len(dd), len(dd))].mean(0) for _ in range(2000)])
        lo, hi = np.percentile(bs, [2.5, 97.5], axis=0)
        print(f"  {k:9s} moving {a[:,0].mean():7.2f} ({dd[:,0].mean():+6.2f} [{lo[0]:+.2f}, {hi[0]:+.2f}])"
              f"  all {a[:,1].mean():7.2f} ({dd[:,1].mean():+6.2f} [{lo[1]:+.2f}, {hi[1]:+.2f}])")
