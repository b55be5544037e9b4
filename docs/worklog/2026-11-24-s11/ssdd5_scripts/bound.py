"""bound.py DUMP.npz TRUEFLOW.npz: what temporal fusion of level-1 predictions could gain, with the simulator's
true motion (diagnosis only). Errors e_t = pred_t - truth_t on M = ROI & LQ valid & truth valid (the bench's
truth_roi pixels); moving = |truth_t - truth_{t-1}| > 1 cm (bench.metrics.moving_mask). Per-frame MSE (mm^2),
mean over frames 1..n-1 with a per-frame bootstrap for the differences."""
import sys
import numpy as np

d = np.load(sys.argv[1]); f = np.load(sys.argv[2])
tr = d["truth"].astype(np.float64); lq = d["lq"]
n, H, W = tr.shape
M = d["roi"] & np.isfinite(lq) & (lq > 0) & np.isfinite(tr) & (tr > 0)
print("truth vs rendered t_hit: max |diff| mm on M", np.nanmax(np.abs(np.where(M, tr - f["zt"], 0))) * 1e3)
uv, zb = f["uv"], f["zb"]
TOL = float(sys.argv[3]) if len(sys.argv) > 3 else 0.01
rng = np.random.default_rng(0)

def carried(e, t, k):
    """e_{t-k} at the true position of frame t's points in frame t-k (nearest pixel), NaN where not visible."""
    u = np.rint(uv[t, k - 1, ..., 0]).astype(np.float64); v = np.rint(uv[t, k - 1, ..., 1])
    ok = np.isfinite(u) & np.isfinite(v)
    ui = np.clip(np.nan_to_num(u), 0, W - 1).astype(int); vi = np.clip(np.nan_to_num(v), 0, H - 1).astype(int)
    ok &= (u >= 0) & (u < W) & (v >= 0) & (v < H)
    ok &= np.abs(tr[t - k][vi, ui] - zb[t, k - 1]) < TOL
    ok &= M[t - k][vi, ui]
    out = np.where(ok, e[t - k][vi, ui], np.nan)
    return out

def study(name, pred, K=3):
    e = pred.astype(np.float64) - tr
    rows = {"L1": [], "same2": [], "true2": [], "true4": [], "truew": []}
    cors = {"same": [], "true": []}
    cov = []
    mov_all = []
    for t in range(1, n):
        mv = M[t] & M[t - 1] & (np.abs(tr[t] - tr[t - 1]) > 0.01)
        st = M[t] & M[t - 1] & ~(np.abs(tr[t] - tr[t - 1]) > 0.01)
        res = {}
        res["L1"] = e[t]
        res["same2"] = 0.5 * (pred[t] + pred[t - 1]) - tr[t]
        c1 = carried(e, t, 1)
        res["true2"] = np.where(np.isfinite(c1), 0.5 * (e[t] + c1), e[t])
        acc, cnt = e[t].copy(), np.ones_like(e[t])
        for k in range(1, min(K, t) + 1):
            c = carried(e, t, k); g = np.isfinite(c)
            acc[g] += c[g]; cnt[g] += 1
        res["true4"] = acc / cnt
        # recursive 0.5 is true2; also exponential with the best fixed weight a (chosen below in post)
        for key in rows:
            if key == "truew":
                continue
            r = res[key]
            rows[key].append([np.mean(r[mv] ** 2), np.mean(r[M[t]] ** 2)])
        g = mv & np.isfinite(c1)
        cov.append([g.sum(), mv.sum()])
        if g.sum() > 10:
            cors["true"].append([e[t][g], c1[g]])
        cors["same"].append([e[t][mv], e[t - 1][mv]])
        mov_all.append(mv)
    print(f"== {name}: frames {n - 1}; moving pixels with a visible true match in t-1: "
          f"{np.sum([c[0] for c in cov]) / np.sum([c[1] for c in cov]):.3f}")
    base = np.array(rows["L1"]) * 1e6
    print(f"  {'':6s} moving mm2 | all mm2 | diff vs L1 moving [95%] | all [95%]")
    for key in ("L1", "same2", "true2", "true4"):
        a = np.array(rows[key]) * 1e6
        dd = a - base
        bs = [dd[rng.integers(0, len(dd), len(dd))].mean(0) for _ in range(2000)]
        lo, hi = np.percentile(bs, [2.5, 97.5], axis=0)
        print(f"  {key:6s} {a[:,0].mean():8.2f} {a[:,1].mean():8.2f}   {dd[:,0].mean():+7.2f} [{lo[0]:+.2f}, {hi[0]:+.2f}]"
              f"   {dd[:,1].mean():+7.2f} [{lo[1]:+.2f}, {hi[1]:+.2f}]")
    for k, v in cors.items():
        x = np.concatenate([a for a, b in v]); y = np.concatenate([b for a, b in v])
        r = np.corrcoef(x, y)[0, 1]
        print(f"  moving-pixel error correlation frame to frame, {k}-pixel/motion: {r:.3f}; independent share 1-rho = {1-r:.3f}")

for key in ("final", "fm", "lstm"):
    study(key, d[key].astype(np.float64))
lqf = np.where(M, d["lq"], np.nan).astype(np.float64)
study("raw LQ", lqf)
