"""posthoc.py DATASET SESSION: two candidate masks evaluated post hoc on an aligned dataset (no truth in the masks):
 vis: visibility: X = ray_lq(p) * z_ref in the HQ camera; masked if every HQ sample of the 2x2 around its projection
      is nearer than z_hq(X) by more than 10 % (the HQ camera saw something in front of X: X unobserved);
 lq:  the LQ sensor's own depth: masked if LQ is finite and farther than the reference by > 10 % within 2 px of a
      reference hole or edge (flatters raw LQ: measured as raw LQ's MSE against the reference before/after).
Prints per mask: masked share of ROI (added to aligned.json's), >0.3 m errors caught, ratio, and for lq the raw
LQ's MSE vs the reference and vs the truth on the scored pixels, before/after."""
import sys, csv, json
import numpy as np, cv2
from common import frame_errors, per_frame, ratio, boot
sys.path.insert(0, '/work/wt/refedge3')
from align.dataset import AlignedDataset
from capture.camera import Intrinsics, Transform
from capture.session import open_session

root, sroot = sys.argv[1], sys.argv[2]
e, share = frame_errors(root)
ds = AlignedDataset(root); meta = ds.meta
Kl, Kh = Intrinsics.from_dict(meta['lq_intrinsics']), Intrinsics.from_dict(meta['hq_intrinsics'])
T = Transform.from_list(meta['T_lq_hq']); Tinv = T.inverse()
sess = open_session(sroot)
rows = list(csv.DictReader(open(f'{root}/frames.csv')))
roi_total = meta['reference_edges']['roi_pixels']
H, W = Kl.height, Kl.width
jj, ii = np.meshgrid(np.arange(W), np.arange(H))
masks = {'vis': [], 'lq': []}
lq_mse = {'before': [0, 0, 0], 'after': [0, 0, 0]}
for f in range(len(ds)):
    ref, lq, roi = ds.reference(f), ds.lq_depth(f), ds.roi(f)
    hq = sess.read_depth('hq', int(rows[f]['hq_frame']))
    has = np.isfinite(ref) & roi
    X = Tinv.apply(Kl.unproject(np.stack([jj[has], ii[has]], 1).astype(float), ref[has].astype(float)))
    uv = Kh.project(X)
    u0, v0 = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
    nearer = np.ones(u0.size, bool)
    for a in (0, 1):
        for b in (0, 1):
            uu, vv = np.clip(u0 + a, 0, Kh.width - 1), np.clip(v0 + b, 0, Kh.height - 1)
            d = hq[vv, uu]
            nearer &= np.isfinite(d) & (d < X[:, 2] / 1.1)
    vis = np.zeros((H, W), bool); vis[has] = nearer
    masks['vis'].append(vis)
    refz = np.where(np.isfinite(ref), ref, np.inf).astype(np.float32)
    k = np.ones((5, 5), np.uint8)
    hole_near = cv2.dilate((~np.isfinite(ref)).astype(np.uint8), k).astype(bool)
    mx = cv2.dilate(np.where(np.isfinite(ref), ref, 0).astype(np.float32), k)
    edge_near = mx > 1.1 * np.where(np.isfinite(ref), ref, np.inf)
    with np.errstate(invalid='ignore'):
        lqm = has & np.isfinite(lq) & (lq > 1.1 * ref) & (hole_near | edge_near)
    masks['lq'].append(lqm)
    sc = np.isfinite(e[f])
    t = ds.truth(f)
    for key, m in (('before', sc), ('after', sc & ~lqm)):
        mm = m & np.isfinite(lq)
        lq_mse[key][0] += np.sum(((lq[mm] - ref[mm]) * 1000.0) ** 2); lq_mse[key][1] += np.sum(((lq[mm] - t[mm]) * 1000.0) ** 2)
        lq_mse[key][2] += mm.sum()
mae0, rmse0 = per_frame(e)
print(f"{root}: base ratio {ratio(mae0, rmse0):.2f} masked {100*share:.2f} %")
for name, ms in masks.items():
    m = np.stack(ms)
    e2 = np.where(m, np.nan, e)
    mae, rmse = per_frame(e2)
    lo, hi = boot(lambda i: ratio(mae[i], rmse[i]), len(mae))
    big = np.abs(np.nan_to_num(e)) > 300
    print(f"  {name}: +{100 * m.sum() / roi_total:.3f} % of ROI masked ({int(m.sum())} px), caught {int((m & big).sum())}/{int(big.sum())} of >0.3 m; "
          f"ratio {ratio(mae, rmse):.2f} [{lo:.2f}, {hi:.2f}]")
b, a = lq_mse['before'], lq_mse['after']
print(f"  raw LQ MSE vs reference {b[0]/b[2]:.0f} -> {a[0]/a[2]:.0f} mm2 ({a[0]/a[2]/(b[0]/b[2]) - 1:+.1%}); vs truth same pixels {b[1]/b[2]:.0f} -> {a[1]/a[2]:.0f} mm2")
