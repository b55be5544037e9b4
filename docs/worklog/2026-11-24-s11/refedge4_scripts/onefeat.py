"""onefeat.py TAG...: each witness of features.py alone: scored pixels ranked by it (ties broken at random; 'sil'
ascending, the others descending), the top B masked (B = budget left under 2 %); > 0.3 m pixels caught and ratio."""
import sys
import numpy as np
from learn import ratio_of

for t in sys.argv[1:]:
    z = np.load(f'/tmp/refedge4/feat_{t}.npz'); X, y, e, f = z['X'], z['y'], z['e'], z['f'].astype(int)
    nf = int(z['shape'][0]); B = int((0.02 - float(z['share'])) * float(z['roi_total']))
    tie = np.random.default_rng(0).random(len(y)) * 1e-6
    out = []
    for j, name in enumerate(z['names']):
        s = (-X[:, j] if name == 'sil' else X[:, j]) + tie
        m = np.zeros(len(s), bool); m[np.argsort(-s)[:B]] = True
        r, (lo, hi) = ratio_of(e, f, nf, m)
        out.append(f"{name} {int((m & y).sum())}/{int(y.sum())} {r:.2f}")
    r0, _ = ratio_of(e, f, nf, np.zeros(len(y), bool))
    print(f"{t} (base {r0:.2f}, budget {B} px): " + " | ".join(out))
