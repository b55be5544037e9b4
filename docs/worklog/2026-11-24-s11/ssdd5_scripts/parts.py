"""parts.py DUMP.npz...: level 2's gain split: lstm - fm (over its input), lstm0 - fm (no memory: state reset every
frame), lstm - lstm0 (the memory), fm - final, lstm - final; moving and all pixels of truth_roi (M = ROI & LQ valid &
truth), per-frame MSE mm^2, per-frame bootstrap (frames 1..n-1)."""
import sys
import numpy as np
for path in sys.argv[1:]:
    d = np.load(path)
    tr = d["truth"].astype(float); lq = d["lq"]
    M = d["roi"] & np.isfinite(lq) & (lq > 0) & np.isfinite(tr) & (tr > 0)
    n = len(tr); rng = np.random.default_rng(0)
    def per(p):
        r = []
        for t in range(1, n):
            mv = M[t] & M[t - 1] & (np.abs(tr[t] - tr[t - 1]) > 0.01)
            e = (p[t].astype(float) - tr[t]) ** 2 * 1e6
            r.append([e[mv].mean(), e[M[t]].mean()])
        return np.array(r)
    P = {k: per(d[k]) for k in ("final", "fm", "lstm", "lstm0")}
    print(f"== {path}: moving / all mm2: " + ", ".join(f"{k} {v[:,0].mean():.2f} / {v[:,1].mean():.2f}" for k, v in P.items()))
    for a, b in (("lstm", "fm"), ("lstm0", "fm"), ("lstm", "lstm0"), ("fm", "final"), ("lstm", "final")):
        dd = P[a] - P[b]
        bs = np.array([dd[rng.integers(0, len(dd), len(dd))].mean(0) for _ in range(2000)])
        lo, hi = np.percentile(bs, [2.5, 97.5], axis=0)
        print(f"  {a:5s} - {b:5s}: moving {dd[:,0].mean():+.2f} [{lo[0]:+.2f}, {hi[0]:+.2f}]   all {dd[:,1].mean():+.2f} [{lo[1]:+.2f}, {hi[1]:+.2f}]")
