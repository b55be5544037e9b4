"""geomcheck.py SESSION LQFRAME HQFRAME R C: HQ truth samples near LQ (R, C), projected with the true T, against LQ truth."""
import sys, json
import numpy as np
sys.path.insert(0, '/work/wt/refedge3')
from capture.camera import Intrinsics, Transform
from capture.truth import read_truth
from capture.session import open_session
s, fl, fh, R, C = sys.argv[1], *map(int, sys.argv[2:6])
tr = read_truth(s); tj = json.load(open(f'{s}/truth/truth.json'))
T = Transform.from_list(tj['T_lq_hq'])
ses = open_session(s)

Kl, Kh = ses.intrinsics('lq', 'depth'), ses.intrinsics('hq', 'depth')
ht, lt = tr.depth('hq', fh), tr.depth('lq', fl)
H, W = ht.shape
jj, ii = np.meshgrid(np.arange(W), np.arange(H))
X = T.apply(Kh.unproject(np.stack([jj.ravel(), ii.ravel()], 1).astype(float), ht.ravel().astype(float)))
uv = Kl.project(X).reshape(H, W, 2)
near = (np.abs(uv[..., 0] - C) < 2) & (np.abs(uv[..., 1] - R) < 2)
for i, j in zip(*np.nonzero(near)):
    u, v = uv[i, j]; z = X.reshape(H, W, 3)[i, j, 2]
    print(f"HQ({i},{j}) t {ht[i,j]:.3f} -> LQ ({u:.2f},{v:.2f}) z {z:.3f}; LQ truth at nearest ({int(round(v))},{int(round(u))}) {lt[int(round(v)), int(round(u))]:.3f}")
np.set_printoptions(precision=2, linewidth=200, suppress=True)
print(lt[R-3:R+4, C-3:C+4])
