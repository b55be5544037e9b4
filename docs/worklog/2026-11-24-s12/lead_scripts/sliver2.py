"""sliver2.py NEW OLD PAIR: the HQ samples the plain warp (strict) puts on the pair's LQ pixels > 300 mm nearer than the
truth (new session): their HQ positions, new depth, old depth (same seed, point-sampled), HQ truth depth."""
import os, sys
os.environ.setdefault("OMP_NUM_THREADS", "1")
import numpy as np
sys.path.insert(0, os.getcwd())
import perf.reference_motion as rm
from align.reference_edges import EdgeRule
rule = EdgeRule.named("strict")
new, old, k = sys.argv[1], sys.argv[2], int(sys.argv[3])
setup, warper, tr, pairs = rm._pairs(new, 10, rule)
i, j, dt = pairs[k]
sess = setup.session
hq = sess.read_depth("hq", int(setup.f_hq[i]))
ref = warper(hq)
truth = tr.depth("lq", int(setup.f_lq[j]))
bad = np.isfinite(ref) & np.isfinite(truth) & (truth - ref > 0.3)
u, v, w, valid = warper.forward_map(hq)
cu, cv = np.round(u).astype(int), np.round(v).astype(int)
ok = valid & np.isfinite(u) & (cu >= 0) & (cv >= 0) & (cu < bad.shape[1]) & (cv < bad.shape[0])
hit = np.zeros(hq.shape, bool)
hit[ok] = bad[cv[ok], cu[ok]]
ys, xs = np.nonzero(hit)
print(f"pair {k}: {bad.sum()} LQ px > 0.3 m nearer; {hit.sum()} HQ samples land on them; HQ rows {ys.min()}-{ys.max()} cols {xs.min()}-{xs.max()}")
s_old = rm._pairs(old, 10, rule)[0]
hq_old = s_old.session.read_depth("hq", int(s_old.f_hq[i]))
hq_t = tr.depth("hq", int(setup.f_hq[i]))
r0 = int(np.median(ys)); c0 = int(np.median(xs))
np.set_printoptions(linewidth=200, precision=2, suppress=True)
for name, a in (("new", hq), ("old", hq_old), ("HQ truth", hq_t)):
    print(name); print(a[r0 - 3:r0 + 4, c0 - 6:c0 + 7])
print("hit"); print(hit[r0 - 3:r0 + 4, c0 - 6:c0 + 7].astype(int))
