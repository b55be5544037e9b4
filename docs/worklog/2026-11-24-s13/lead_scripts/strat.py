"""strat.py PREDS.npz [K ...]: ranking agreement (reference vs truth) in the interior / edge strata, edges from the
reference itself: 3x3 span of finite reference depth > REL x depth (REL env, default 0.03); HOLES=1 also counts a
pixel next to a reference hole (inside the ROI) as an edge. Stratum 'edge': distance to an edge pixel <= K."""
import os, sys
import numpy as np, cv2
z = np.load(sys.argv[1]); ks = [float(k) for k in sys.argv[2:]] or [1.0]
REL = float(os.environ.get("REL", 0.03)); HOLES = os.environ.get("HOLES") == "1"
M = ["raw", "gaussian", "bilateral", "joint_bilateral", "rolling_guidance", "ddrnet", "ddrnet_refine", "ddd", "ssdd_unet", "ssdd_lstm"]
ref, tru, roi = z["reference"], z["truth"], z["roi"].astype(bool)
P = {m: z[m] for m in M}
n = ref.shape[0]
FILL = int(os.environ.get("FILL", 0))
def fill_far(r, px):
    f = np.where(np.isfinite(r) & (r > 0), r, 0).astype(np.float32)
    for _ in range(px):
        f = np.where(f > 0, f, cv2.dilate(f, np.ones((3, 3), np.uint8)))
    return np.where(f > 0, f, np.nan)
def edges(r, roi_f):
    valid = np.isfinite(r) & (r > 0)
    if FILL: r = fill_far(r, FILL)
    f = np.isfinite(r) & (r > 0)
    hi = cv2.dilate(np.where(f, r, -np.inf).astype(np.float32), np.ones((3, 3), np.uint8))
    lo = cv2.erode(np.where(f, r, np.inf).astype(np.float32), np.ones((3, 3), np.uint8))
    e = f & (hi - lo > REL * np.where(f, r, 1))
    if HOLES:
        e |= f & (cv2.erode((f | ~roi_f).astype(np.uint8), np.ones((3, 3), np.uint8)) == 0)
    return e & valid if os.environ.get('VALIDONLY') else e
rng = np.random.default_rng(0); B = rng.integers(0, n, (2000, n))
def ci(d):
    b = d[B].mean(1); return d.mean(), np.percentile(b, 2.5), np.percentile(b, 97.5)
for K in ks:
    mse = {s: {w: np.zeros((len(M), n)) for w in ("hq", "truth")} for s in ("all", "interior", "edge")}
    share = np.zeros(n)
    for i in range(n):
        r, t = ref[i].astype(np.float64), tru[i].astype(np.float64)
        base = roi[i] & np.isfinite(r) & (r > 0) & np.isfinite(t)
        dist = cv2.distanceTransform((~edges(ref[i], roi[i])).astype(np.uint8), cv2.DIST_L2, 5)
        sel = {"all": base, "interior": base & (dist > K), "edge": base & (dist <= K)}
        share[i] = sel["edge"].sum() / base.sum()
        for j, m in enumerate(M):
            p = P[m][i].astype(np.float64); ok = np.isfinite(p) & (p > 0)
            for s, q in sel.items():
                q = q & ok
                mse[s]["hq"][j, i] = np.mean(((p - r)[q] * 1000) ** 2)
                mse[s]["truth"][j, i] = np.mean(((p - t)[q] * 1000) ** 2)
    print(f"K={K:g} REL={REL} HOLES={HOLES} FILL={FILL}: edge share {share.mean()*100:.1f} %")
    for s in ("all", "interior", "edge"):
        for metric in ("MSE", "RMSE"):
            V = {w: (mse[s][w] if metric == "MSE" else np.sqrt(mse[s][w])) for w in ("hq", "truth")}
            oh = [M[j] for j in np.argsort(V["hq"].mean(1))]; ot = [M[j] for j in np.argsort(V["truth"].mean(1))]
            wrong, flips = [], 0
            for a in range(len(M)):
                for b in range(a + 1, len(M)):
                    dh, dt = ci(V["hq"][a] - V["hq"][b]), ci(V["truth"][a] - V["truth"][b])
                    if np.sign(dh[0]) != np.sign(dt[0]):
                        flips += 1
                        if (dh[1] > 0 or dh[2] < 0) and (dt[1] > 0 or dt[2] < 0):
                            wrong.append(f"{M[a]}-{M[b]} hq {dh[0]:+.2f}[{dh[1]:+.2f},{dh[2]:+.2f}] truth {dt[0]:+.2f}[{dt[1]:+.2f},{dt[2]:+.2f}]")
            print(f"  {s:8s} {metric:4s} same order {oh == ot}, flips {flips}, wrong {len(wrong)} {wrong}")
    u, g = M.index("ssdd_unet"), M.index("rolling_guidance")
    for s in ("all", "interior", "edge"):
        print(f"  {s}: RGF-UNet MSE hq %+.2f [%+.2f,%+.2f]" % ci(mse[s]['hq'][g] - mse[s]['hq'][u]), " truth %+.2f [%+.2f,%+.2f]" % ci(mse[s]['truth'][g] - mse[s]['truth'][u]))
