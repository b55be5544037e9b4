"""geomall.py SESSION LQFRAME HQFRAME: HQ truth projected with the true T; samples landing within 0.15 px of an LQ pixel
centre where the LQ truth is farther by > 5 % (impossible for a static opaque scene seen at one instant)."""
import sys, json
import numpy as np
sys.path.insert(0, '/work/wt/refedge3')
from capture.camera import Transform
from capture.truth import read_truth
from capture.session import open_session
s, fl, fh = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
tr = read_truth(s); T = Transform.from_list(json.load(open(f'{s}/truth/truth.json'))['T_lq_hq'])
ses = open_session(s); Kl, Kh = ses.intrinsics('lq', 'depth'), ses.intrinsics('hq', 'depth')
ht, lt = tr.depth('hq', fh), tr.depth('lq', fl)
H, W = ht.shape
jj, ii = np.meshgrid(np.arange(W), np.arange(H))
ok = np.isfinite(ht.ravel())
X = T.apply(Kh.unproject(np.stack([jj.ravel(), ii.ravel()], 1)[ok].astype(float), ht.ravel()[ok].astype(float)))
uv = Kl.project(X)
r, c = np.round(uv[:, 1]).astype(int), np.round(uv[:, 0]).astype(int)
ins = (r >= 0) & (c >= 0) & (r < Kl.height) & (c < Kl.width) & (np.hypot(uv[:, 0] - c, uv[:, 1] - r) < 0.15)
z = X[ins, 2]; l = lt[r[ins], c[ins]]
bad = l > z * 1.05
print(f"{ins.sum()} samples at LQ centres; LQ truth farther by >5 %: {bad.sum()}; nearer by >5 %: {(l < z * 0.95).sum()}")
for k in np.flatnonzero(bad)[:10]:
    print(f"  LQ ({r[ins][k]},{c[ins][k]}) z {z[k]:.3f} LQ truth {l[k]:.3f}")
