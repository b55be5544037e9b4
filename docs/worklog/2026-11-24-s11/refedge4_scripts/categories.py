"""categories.py DATASET SESSION: each ROI pixel > 0.3 m off, by what put the reference there (diagnosis; uses the truth):
 mix  - the covering splat's point, or an axis neighbour of its quadrant, is a time-of-flight mix (HQ depth > 5 cm off the
        HQ truth) linked into the near surface: the near surface extended by a flying pixel within noise of it;
 cut  - a quadrant cut at the diagonal (the triangle of three true near samples, far diagonal): the silhouette is concave;
 full - a full cell / axis reach of true near samples: the LQ sees through a slit the HQ samples do not (thinner than one
        HQ step, or the tip of a closing wedge that moved in the ~0.5 ms between the two exposures);
 other - no covering splat of the reference's depth found (motion-carried or a far-side error).
Prints counts for > 0.3 m and > 1 m, and the pixels."""
import sys, csv, math
import numpy as np
from common import frame_errors
sys.path.insert(0, '/work/wt/refedge4')
from align.dataset import AlignedDataset
from align.warp_reference import _project_all, default_footprint
from align.warp_splat import splat_offsets
from capture.camera import Intrinsics, Transform
from capture.session import open_session
from capture.truth import read_truth

root, sroot = sys.argv[1], sys.argv[2]
e, _ = frame_errors(root)
ds = AlignedDataset(root); meta = ds.meta
Kl, Kh = Intrinsics.from_dict(meta['lq_intrinsics']), Intrinsics.from_dict(meta['hq_intrinsics'])
T = Transform.from_list(meta['T_lq_hq'])
rows = list(csv.DictReader(open(f'{root}/frames.csv')))
sess, truth = open_session(sroot), read_truth(sroot)
offsets = splat_offsets(default_footprint(Kh, Kl))
cache, counts, lines = {}, {}, []
for f, r, c in zip(*np.nonzero(np.abs(np.nan_to_num(e)) > 300)):
    fh = int(rows[f]['hq_frame'])
    if fh not in cache:
        hq = sess.read_depth('hq', fh); g = _project_all(np.asarray(hq, np.float64), Kh, Kl, T, 0.03); g.dst_shape = Kl.shape
        cache = {fh: (hq, truth.depth('hq', fh), g)}
    hq, hqt, g = cache[fh]
    ref = ds.reference(f)[r, c]
    mixed = lambda i, j: g.inside(i, j) and np.isfinite(hq[i, j]) and abs(hq[i, j] - hqt[i, j]) > 0.05
    cats = []
    for i, j in np.argwhere((g.w > 0) & (np.abs(g.u - c) < 2.5) & (np.abs(g.v - r) < 2.5)):
        grads, conts = g.gradients(i, j)
        (nx, gx), (ny, gy) = grads
        if nx == 0 or ny == 0 or abs(1 / g.w[i, j] - ref) > 0.05 * ref:
            continue
        J = np.array([[gx[0], gy[0]], [gx[1], gy[1]]])
        if abs(np.linalg.det(J)) < 1e-9:
            continue
        delta = np.linalg.inv(J) @ np.array([c - g.u[i, j], r - g.v[i, j]])
        lim = {(ax, sg): 1.0 if conts[ax][(sg + 1) // 2] else 0.0 for ax in (0, 1) for sg in (-1, 1)}
        if not all(abs(delta[ax]) < lim[(ax, 1 if delta[ax] > 0 else -1)] for ax in (0, 1)):
            continue
        if (c - math.floor(g.u[i, j]), r - math.floor(g.v[i, j])) not in offsets:
            continue
        sx, sy = (1 if delta[0] > 0 else -1), (1 if delta[1] > 0 else -1)
        if mixed(i, j) or mixed(i, j + sx) or mixed(i + sy, j):
            cats.append('mix'); continue
        cut = not (g.cont(i, j + sx, i + sy, j + sx) or g.cont(i + sy, j, i + sy, j + sx))
        cats.append('cut' if cut else 'full')
    cat = 'mix' if 'mix' in cats else ('full' if 'full' in cats else ('cut' if 'cut' in cats else 'other'))
    big = abs(e[f, r, c]) > 1000
    counts[(cat, big)] = counts.get((cat, big), 0) + 1
    lines.append(f"  f{f} ({r},{c}) err {e[f, r, c]:+.0f} {cat}")
tot = lambda cat: counts.get((cat, False), 0) + counts.get((cat, True), 0)
print(root, " ".join(f"{cat}: {tot(cat)} ({counts.get((cat, True), 0)} >1 m)" for cat in ('mix', 'cut', 'full', 'other')))
print("\n".join(lines))
