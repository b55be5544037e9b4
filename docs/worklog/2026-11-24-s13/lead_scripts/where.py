"""where.py PREDS.npz: where (by reference-observable features) the reference's bias between RGF and SSDD UNet lies.
bias per pixel = -2[(u-t)(r-t) - (g-t)(r-t)] (mm^2), i.e. (MSE_ref - MSE_truth)(UNet) - (...)(RGF) contribution."""
import sys
import numpy as np, cv2
z = np.load(sys.argv[1]); ref, tru, roi = z["reference"], z["truth"], z["roi"].astype(bool)
U, G = z["ssdd_unet"], z["rolling_guidance"]
n = ref.shape[0]
def span(d):
    f = np.isfinite(d) & (d > 0)
    hi = cv2.dilate(np.where(f, d, 0).astype(np.float32), np.ones((3, 3), np.uint8))
    lo = cv2.erode(np.where(f, d, 1e3).astype(np.float32), np.ones((3, 3), np.uint8))
    return f & (hi - lo > 0.03 * np.where(f, d, 1))
def fill_far(r, px=3):
    f = np.where(np.isfinite(r) & (r > 0), r, 0).astype(np.float32)
    for _ in range(px):
        f = np.where(f > 0, f, cv2.dilate(f, np.ones((3, 3), np.uint8)))
    return np.where(f > 0, f, np.nan)
feats = {"d_hole": [], "d_refedge": [], "d_filledge": [], "d_truthedge": []}
bias, tot = [], 0
for i in range(n):
    r, t, u, g = (a[i].astype(np.float64) for a in (ref, tru, U, G))
    m = roi[i] & np.isfinite(r) & (r > 0) & np.isfinite(t) & np.isfinite(u) & np.isfinite(g)
    e = (r - t) * 1000
    b = -2 * (((u - t) * 1000 * e) - ((g - t) * 1000 * e)) / m.sum() / n
    hole = roi[i] & ~(np.isfinite(r) & (r > 0))
    dist = lambda mask: cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, 5)
    fe = {"d_hole": dist(hole), "d_refedge": dist(span(r)), "d_filledge": dist(span(fill_far(r))), "d_truthedge": dist(span(t))}
    for k in feats: feats[k].append(fe[k][m])
    bias.append(b[m])
bias = np.concatenate(bias); print(f"total bias (UNet favoured by) {bias.sum():+.2f} mm^2")
for k in feats:
    v = np.concatenate(feats[k])
    print(k, " | ".join(f"<={c:g}: px {np.mean(v <= c)*100:4.1f}% bias {bias[v <= c].sum():+5.2f}" for c in (1, 1.5, 2, 3, 5)))
