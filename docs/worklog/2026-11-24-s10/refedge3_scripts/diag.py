"""diag.py DATASET SESSION [thr_mm]: every scored pixel off by more than thr (300 mm): what the HQ saw there.
Diagnosis only (uses the truth, never in a rule)."""
import sys, json
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
ds = AlignedDataset(root)
meta = ds.meta
Kl, Kh = Intrinsics.from_dict(meta['lq_intrinsics']), Intrinsics.from_dict(meta['hq_intrinsics'])
T = Transform.from_list(meta['T_lq_hq'])
warper = DepthWarper(Kh, Kl, T, edge_rel=0.03, edge_reach=0.0)
sess = open_session(sroot)
truth = read_truth(sroot)
import csv
rows = list(csv.DictReader(open(f'{root}/frames.csv')))
Tinv = T.inverse()
np.set_printoptions(precision=2, linewidth=200, suppress=True)
for f, r, c in zip(*np.nonzero(np.abs(np.nan_to_num(e)) > thr)):
    ref, tru, lq = ds.reference(f), ds.truth(f), ds.lq_depth(f)
    fh = int(rows[f]['hq_frame'])
    hq = sess.read_depth('hq', fh)
    hqt = truth.depth('hq', fh)
    print(f"=== frame {f} px (r{r}, c{c}) ref {ref[r, c]:.3f} truth {tru[r, c]:.3f} lq {lq[r, c]:.3f} err {e[f, r, c]:+.0f} mm, hq frame {fh}")
    sl = np.s_[max(r - 3, 0):r + 4, max(c - 3, 0):c + 4]
    print("ref\n", ref[sl]); print("truth\n", tru[sl]); print("lq\n", lq[sl])
    # visibility: X at the reference depth, and at the truth depth, projected into HQ
    for name, z in (("ref", ref[r, c]), ("truth", tru[r, c])):
        X = Kl.unproject(np.array([[c, r]], float), np.array([z]))
        Xh = Tinv.apply(X)
        uv = Kh.project(Xh)[0]
        j, i = int(round(uv[0])), int(round(uv[1]))
        print(f"  X@{name}: HQ (u {uv[0]:.2f}, v {uv[1]:.2f}) z_hq {Xh[0, 2]:.3f}; HQ depth 3x3\n", hq[i - 1:i + 2, j - 1:j + 2],
              "\n  HQ truth 3x3\n", hqt[i - 1:i + 2, j - 1:j + 2])
    u, v, w, valid = warper.forward_map(hq)
    near = valid & (np.abs(u - c) < 1.6) & (np.abs(v - r) < 1.6)
    for i, j in zip(*np.nonzero(near)):
        print(f"  HQ sample ({i},{j}) d {hq[i, j]:.3f} truth {hqt[i, j]:.3f} -> (u {u[i, j]:.2f}, v {v[i, j]:.2f}) z {1 / w[i, j]:.3f}")
