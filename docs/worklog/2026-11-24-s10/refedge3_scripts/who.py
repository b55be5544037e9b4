"""who.py DATASET SESSION FRAME ROW COL: the splats that land on one LQ pixel, per HQ point (warp_reference's
rules, edge_reach 0), with the source-grid offset delta, links, cut, and whether it counts."""
import sys, csv, math
import numpy as np
sys.path.insert(0, '/work/wt/refedge3')
from align.dataset import AlignedDataset
from align.warp_reference import _project_all, default_footprint
from align.warp_splat import splat_offsets
from capture.camera import Intrinsics, Transform
from capture.session import open_session
from capture.truth import read_truth

root, sroot, f, r, c = sys.argv[1], sys.argv[2], *map(int, sys.argv[3:6])
ds = AlignedDataset(root); meta = ds.meta
Kl, Kh = Intrinsics.from_dict(meta['lq_intrinsics']), Intrinsics.from_dict(meta['hq_intrinsics'])
T = Transform.from_list(meta['T_lq_hq'])
rows = list(csv.DictReader(open(f'{root}/frames.csv'))); fh = int(rows[f]['hq_frame'])
hq = open_session(sroot).read_depth('hq', fh); hqt = read_truth(sroot).depth('hq', fh)
g = _project_all(np.asarray(hq, np.float64), Kh, Kl, T, 0.03); g.dst_shape = Kl.shape
k = default_footprint(Kh, Kl); offsets = splat_offsets(k)
print('ref', ds.reference(f)[r, c], 'truth', ds.truth(f)[r, c])
cand = np.argwhere((g.w > 0) & (np.abs(g.u - c) < 2.5) & (np.abs(g.v - r) < 2.5))
for i, j in cand:
    grads, conts = g.gradients(i, j)
    (nx, gx), (ny, gy) = grads
    s = f"HQ({i},{j}) d {hq[i,j]:.3f} t {hqt[i,j]:.3f} uv ({g.u[i,j]:.2f},{g.v[i,j]:.2f}) cont x{conts[0]} y{conts[1]}"
    if nx == 0 or ny == 0:
        print(s, 'dropped'); continue
    J = np.array([[gx[0], gy[0]], [gx[1], gy[1]]]); Jinv = np.linalg.inv(J)
    fu, fv = math.floor(g.u[i, j]), math.floor(g.v[i, j])
    for a, b in offsets:
        if (fu + a, fv + b) == (c, r):
            delta = Jinv @ np.array([c - g.u[i, j], r - g.v[i, j]])
            lim = {(ax, sg): 1.0 if conts[ax][(sg + 1) // 2] else 0.0 for ax in (0, 1) for sg in (-1, 1)}
            ins = all(abs(delta[ax]) < lim[(ax, 1 if delta[ax] > 0 else -1)] for ax in (0, 1))
            sx, sy = (1 if delta[0] > 0 else -1), (1 if delta[1] > 0 else -1)
            cut = lim[(0, sx)] == 1 and lim[(1, sy)] == 1 and not (g.cont(i, j + sx, i + sy, j + sx) or g.cont(i + sy, j, i + sy, j + sx))
            s += f" -> delta ({delta[0]:+.2f},{delta[1]:+.2f}) inside {ins} cut {cut} |d|1 {abs(delta[0])+abs(delta[1]):.2f} J {J.round(2).tolist()}"
    print(s)
