"""classify.py DATASET SESSION [thr_mm]: per large-error pixel, the HQ samples that project within 1.6 px at the
reference's depth (within 3 %): are they true samples (HQ truth agrees) or mixes (HQ truth > 5 cm off)?
Also the visibility test: X = ray_lq(p) z_ref in HQ, its HQ depth at the nearest pixel, and the 3x3 max.
Diagnosis only (uses the truth)."""
import sys, csv
import numpy as np
from common import frame_errors
sys.path.insert(0, '/work/wt/refedge3')
from align.dataset import AlignedDataset
from align.warp import DepthWarper
from capture.camera import Intrinsics, Transform
from capture.session import open_session
from capture.truth import read_truth

root, sroot = sys.argv[1], sys.argv[2]
thr = float(sys.argv[3]) if len(sys.argv) > 3 else 300
e, _ = frame_errors(root)
ds = AlignedDataset(root); meta = ds.meta
Kl, Kh = Intrinsics.from_dict(meta['lq_intrinsics']), Intrinsics.from_dict(meta['hq_intrinsics'])
T = Transform.from_list(meta['T_lq_hq']); Tinv = T.inverse()
warper = DepthWarper(Kh, Kl, T, edge_rel=0.03, edge_reach=0.0)
sess = open_session(sroot); truth = read_truth(sroot)
rows = list(csv.DictReader(open(f'{root}/frames.csv')))
cache = {}
for f, r, c in zip(*np.nonzero(np.abs(np.nan_to_num(e)) > thr)):
    ref, tru = ds.reference(f)[r, c], ds.truth(f)[r, c]
    fh = int(rows[f]['hq_frame'])
    if fh not in cache:
        hq = sess.read_depth('hq', fh); cache[fh] = (hq, truth.depth('hq', fh), warper.forward_map(hq))
    hq, hqt, (u, v, w, valid) = cache[fh]
    near = valid & (np.abs(u - c) < 1.6) & (np.abs(v - r) < 1.6) & (np.abs(1 / np.maximum(w, 1e-9) - ref) < 0.03 * ref)
    kinds = ['mix' if abs(hq[i, j] - hqt[i, j]) > 0.05 else 'true' for i, j in zip(*np.nonzero(near))]
    X = Kl.unproject(np.array([[c, r]], float), np.array([ref])); Xh = Tinv.apply(X); uv = Kh.project(Xh)[0]
    j, i = int(round(uv[0])), int(round(uv[1]))
    Xt = Tinv.apply(Kl.unproject(np.array([[c, r]], float), np.array([tru]))); uvt = Kh.project(Xt)[0]
    jt, it = int(round(uvt[0])), int(round(uvt[1]))
    print(f"f{f:2d} ({r},{c}) ref {ref:.2f} tru {tru:.2f} | splatters {','.join(kinds)} | X_ref->HQ({i},{j}) z {Xh[0,2]:.2f} hq {hq[i,j]:.2f} "
          f"hqtruth {hqt[i,j]:.2f} | X_tru->HQ({it},{jt}) z {Xt[0,2]:.2f} hq {hq[it,jt]:.2f} hqtruth {hqt[it,jt]:.2f}")
