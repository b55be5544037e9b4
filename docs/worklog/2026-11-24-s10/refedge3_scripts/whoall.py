"""whoall.py DATASET SESSION [thr]: for every large-error pixel, the splats that cover it (inside), per HQ point:
truth of the point (mix?), source-grid delta, whether its quadrant is cut (concave corner), |delta|_1. Diagnosis only."""
import sys, csv, math
import numpy as np
from common import frame_errors
sys.path.insert(0, '/work/wt/refedge3')
from align.dataset import AlignedDataset
from align.warp_reference import _project_all, default_footprint
from align.warp_splat import splat_offsets
from capture.camera import Intrinsics, Transform
from capture.session import open_session
from capture.truth import read_truth

root, sroot = sys.argv[1], sys.argv[2]
thr = float(sys.argv[3]) if len(sys.argv) > 3 else 300
e, _ = frame_errors(root)
ds = AlignedDataset(root); meta = ds.meta
Kl, Kh = Intrinsics.from_dict(meta['lq_intrinsics']), Intrinsics.from_dict(meta['hq_intrinsics'])
T = Transform.from_list(meta['T_lq_hq'])
rows = list(csv.DictReader(open(f'{root}/frames.csv')))
sess, truth = open_session(sroot), read_truth(sroot)
k = default_footprint(Kh, Kl); offsets = splat_offsets(k)
cache = {}
for f, r, c in zip(*np.nonzero(np.abs(np.nan_to_num(e)) > thr)):
    fh = int(rows[f]['hq_frame'])
    if fh not in cache:
        hq = sess.read_depth('hq', fh); g = _project_all(np.asarray(hq, np.float64), Kh, Kl, T, 0.03); g.dst_shape = Kl.shape
        cache = {fh: (hq, truth.depth('hq', fh), g)}
    hq, hqt, g = cache[fh]
    ref = ds.reference(f)[r, c]
    out = []
    for i, j in np.argwhere((g.w > 0) & (np.abs(g.u - c) < 2.5) & (np.abs(g.v - r) < 2.5)):
        grads, conts = g.gradients(i, j)
        (nx, gx), (ny, gy) = grads
        if nx == 0 or ny == 0 or abs(1 / g.w[i, j] - ref) > 0.05 * ref:
            continue
        J = np.array([[gx[0], gy[0]], [gx[1], gy[1]]]); Jinv = np.linalg.inv(J)
        delta = Jinv @ np.array([c - g.u[i, j], r - g.v[i, j]])
        lim = {(ax, sg): 1.0 if conts[ax][(sg + 1) // 2] else 0.0 for ax in (0, 1) for sg in (-1, 1)}
        ins = all(abs(delta[ax]) < lim[(ax, 1 if delta[ax] > 0 else -1)] for ax in (0, 1))
        fu, fv = math.floor(g.u[i, j]), math.floor(g.v[i, j])
        if not ins or (c - fu, r - fv) not in offsets:
            continue
        sx, sy = (1 if delta[0] > 0 else -1), (1 if delta[1] > 0 else -1)
        cut = not (g.cont(i, j + sx, i + sy, j + sx) or g.cont(i + sy, j, i + sy, j + sx))
        diag = hq[i + sy, j + sx]
        out.append(f"[HQ({i},{j}) {'MIX' if abs(hq[i,j]-hqt[i,j]) > 0.05 else 'ok'} d=({delta[0]:+.2f},{delta[1]:+.2f}) "
                   f"{'CUT' if cut else 'full'} l1 {abs(delta[0])+abs(delta[1]):.2f} diag {diag:.2f}]")
    print(f"f{f:2d} ({r},{c}) ref {ref:.2f} tru {ds.truth(f)[r, c]:.2f}: " + " ".join(out))
