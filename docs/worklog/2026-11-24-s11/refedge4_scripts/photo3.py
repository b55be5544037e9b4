"""photo3.py DATASET SESSION: the far hypothesis seen by the HQ colour camera (no truth in the test). Background
depth bg(p) = align.roi.background_depth of the dataset's references (90th percentile over frames); X_far =
ray_lq(p) bg(p). If the HQ colour camera sees X_far (the HQ depth warped onto the HQ colour image is not nearer than
X_far / 1.05 at its projection) and the LQ colour matches the HQ colour there (3x3 minimum, RGB) better than at the
reference's own point X_near by a margin, the pixel is a candidate: the LQ sees the background through it.
Prints, for the > 0.3 m pixels, visibility and the two scores, and the ratio / caught / masked for a few margins."""
import sys, csv
import numpy as np
from common import frame_errors, per_frame, ratio
from photo2 import colour_dist
sys.path.insert(0, '/work/wt/refedge4')
from align.dataset import AlignedDataset
from align.roi import background_depth
from align.warp import DepthWarper
from capture.camera import Intrinsics, Transform
from capture.session import open_session

root, sroot = sys.argv[1], sys.argv[2]
e, share = frame_errors(root)
ds = AlignedDataset(root); meta = ds.meta; sess = open_session(sroot); tot = meta['reference_edges']['roi_pixels']
rows = list(csv.DictReader(open(f'{root}/frames.csv')))
Kl, Kh = Intrinsics.from_dict(meta['lq_intrinsics']), Intrinsics.from_dict(meta['hq_intrinsics'])
Khc = sess.intrinsics('hq', 'color')
T_hqc_hq = sess.sensors['hq'].T_depth_color.inverse()
T = T_hqc_hq @ Transform.from_list(meta['T_lq_hq']).inverse()
warp_col = DepthWarper(Kh, Khc, T_hqc_hq, edge_reach=0.0)
refs = np.stack([ds.reference(f) for f in range(len(ds))])
bg = background_depth(refs)
H, W = Kl.height, Kl.width
jj, ii = np.meshgrid(np.arange(W), np.arange(H))
NEAR, FAR, VIS = (np.full(e.shape, np.nan) for _ in range(3))
for f in range(len(ds)):
    sc = np.isfinite(e[f]) & np.isfinite(bg) & (bg > 1.1 * np.nan_to_num(refs[f], nan=np.inf))
    c = ds.lq_color(f).astype(np.float32)
    hqf = int(rows[f]['hq_frame'])
    hqc = sess.read_color('hq', hqf).astype(np.float32); dcol = warp_col(sess.read_depth('hq', hqf))
    pix = np.stack([jj[sc], ii[sc]], 1).astype(float)
    Xn = T.apply(Kl.unproject(pix, refs[f][sc].astype(float))); Xf = T.apply(Kl.unproject(pix, bg[sc].astype(float)))
    NEAR[f][sc] = colour_dist(c[sc], Xn, Khc, hqc); FAR[f][sc] = colour_dist(c[sc], Xf, Khc, hqc)
    uv = Khc.project(Xf); cu = np.clip(np.round(uv[:, 0]).astype(int), 0, Khc.width - 1); cv = np.clip(np.round(uv[:, 1]).astype(int), 0, Khc.height - 1)
    dz = dcol[cv, cu]
    VIS[f][sc] = ~(np.isfinite(dz) & (dz < Xf[:, 2] / 1.05))
big = np.abs(np.nan_to_num(e)) > 300
print(f"{root}: candidates (bg > 1.1 z_ref) {np.isfinite(NEAR).sum()}, of them X_far visible {np.nansum(VIS == 1)}; budget {int((0.02 - share) * tot)} px")
for f, i, j in zip(*np.nonzero(big)):
    print(f"  f{f} ({i},{j}) e {e[f, i, j]:.0f} bg {bg[i, j]:.2f} vis {VIS[f, i, j]} near {NEAR[f, i, j]:.1f} far {FAR[f, i, j]:.1f}")
for margin in (0, 10, 20, 30):
    m = (VIS == 1) & (NEAR - FAR > margin)
    mae, rmse = per_frame(np.where(m, np.nan, e))
    print(f"  vis & near - far > {margin}: +{100 * m.sum() / tot:.2f} % ({m.sum()} px), caught {np.sum(m & big)}/{big.sum()}, ratio {ratio(mae, rmse):.2f}")
