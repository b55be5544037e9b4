"""lqedge_t.py TAG...: the LQ colour edge as a per-pixel rule (features.py's lqedge >= t, no budget ranking): per t,
the added masked share, total masked (with aligned.json's), > 0.3 m caught, ratio and the paired change (frame
bootstrap 1000) against no mask."""
import sys
import numpy as np
from learn import ratio_of

for t in sys.argv[1:]:
    z = np.load(f'/tmp/refedge4/feat_{t}.npz'); X, y, e, f = z['X'], z['y'], z['e'], z['f'].astype(int)
    nf = int(z['shape'][0]); tot = float(z['roi_total']); share = float(z['share'])
    s = X[:, list(z['names']).index('lqedge')]
    a = np.abs(e); n = np.bincount(f, minlength=nf)
    out = []
    for thr in (40, 60, 80):
        m = s >= thr
        ok = ~m; n2 = np.bincount(f[ok], minlength=nf)
        mae0, rm0 = np.bincount(f, a, nf) / n, np.sqrt(np.bincount(f, a * a, nf) / n)
        mae1, rm1 = np.bincount(f[ok], a[ok], nf) / n2, np.sqrt(np.bincount(f[ok], a[ok] ** 2, nf) / n2)
        rng = np.random.default_rng(0)
        d = [rm1[i].mean() / mae1[i].mean() - rm0[i].mean() / mae0[i].mean() for i in (rng.integers(0, nf, nf) for _ in range(1000))]
        lo, hi = np.percentile(d, [2.5, 97.5])
        out.append(f"t{thr}: +{100*m.sum()/tot:.2f}% (tot {100*(share+m.sum()/tot):.2f}%) {int((m&y).sum())}/{int(y.sum())} "
                   f"{rm0.mean()/mae0.mean():.2f}->{rm1.mean()/mae1.mean():.2f} [{lo:+.2f},{hi:+.2f}]")
    print(t, " | ".join(out))
