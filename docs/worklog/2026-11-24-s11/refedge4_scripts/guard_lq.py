"""guard_lq.py TAG...: does the best colour witness (the LQ colour edge, features.py's lqedge; its top B pixels
masked, B = budget left under 2 %) flatter the raw LQ depth? Raw LQ's MSE against the reference and against the
truth on the scored pixels where the LQ has depth, before and after the mask (as refedge3's posthoc.py)."""
import sys
import numpy as np
sys.path.insert(0, '/work/wt/refedge4')
from align.dataset import AlignedDataset
from common import frame_errors

for t in sys.argv[1:]:
    root = f'/tmp/refedge4/al_base_{t}'
    z = np.load(f'/tmp/refedge4/feat_{t}.npz'); X, f = z['X'], z['f'].astype(int)
    B = int((0.02 - float(z['share'])) * float(z['roi_total']))
    j = list(z['names']).index('lqedge')
    s = X[:, j] + np.random.default_rng(0).random(len(f)) * 1e-6
    m = np.zeros(len(s), bool); m[np.argsort(-s)[:B]] = True
    e, _ = frame_errors(root); ds = AlignedDataset(root)
    acc = {k: [0.0, 0.0, 0] for k in ('before', 'after')}
    off = 0
    for fr in range(len(ds)):
        sc = np.isfinite(e[fr]); n = int(sc.sum()); mf = m[off:off + n]; off += n
        ref, lq, tr = ds.reference(fr)[sc], ds.lq_depth(fr)[sc], ds.truth(fr)[sc]
        for k, keep in (('before', np.ones(n, bool)), ('after', ~mf)):
            ok = keep & np.isfinite(lq)
            acc[k][0] += np.sum(((lq[ok] - ref[ok]) * 1e3) ** 2); acc[k][1] += np.sum(((lq[ok] - tr[ok]) * 1e3) ** 2); acc[k][2] += ok.sum()
    b, a = acc['before'], acc['after']
    print(f"{t}: masked {m.sum()} px; raw LQ MSE vs reference {b[0]/b[2]:.1f} -> {a[0]/a[2]:.1f} mm2 ({a[0]/a[2]/(b[0]/b[2]) - 1:+.1%}); "
          f"vs truth, same pixels {b[1]/b[2]:.1f} -> {a[1]/a[2]:.1f} mm2 ({a[1]/a[2]/(b[1]/b[2]) - 1:+.1%})")
