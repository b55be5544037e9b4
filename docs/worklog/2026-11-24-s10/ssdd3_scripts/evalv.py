"""evalv.py VAL.npz SESSION.npz [...]: variants of level 2's output, parameters fitted on VAL (the corpus's
validation sequence, against its reference on the 2-sigma gate's ROI pixels), scored per frame against the
truth on every ROI pixel with LQ depth (truth_roi), all and moving (truth changed > 1 cm since the previous frame);
paired bootstrap as perf/ssdd_paired.py."""
import sys
import numpy as np

NZ2 = 0.08 / (600.0 * 0.055)


def load(p):
    z = np.load(p)
    return {k: z[k] for k in z.files}


def frame_mean(d, c, mask):
    """per-frame mean of c over mask -> (F,1,1)"""
    n = mask.sum(axis=(1, 2))
    s = np.where(mask, c, 0).sum(axis=(1, 2))
    return (s / np.maximum(n, 1))[:, None, None]


def parts(d):
    m = d["roi"] & np.isfinite(d["lq"])
    c = d["lstm"] - d["fm"]
    mu = frame_mean(d, c, m)
    return m, c, mu


def fit(v):
    """least squares / L1 fits on the validation sequence's gated pixels"""
    m, c, mu = parts(v)
    ref, lq = v["ref"], v["lq"]
    with np.errstate(invalid="ignore"):
        g = m & np.isfinite(ref) & (np.abs(ref - lq) <= 0.005 + 2 * NZ2 * np.nan_to_num(lq) ** 2)
    r = (ref - v["fm"])[g]; cc = c[g]; mm = np.broadcast_to(mu, c.shape)[g]; z = (c - mu)[g]
    alpha = float(cc @ r / (cc @ cc))
    beta = float(mm @ (r - z) / (mm @ mm))
    A = np.stack([z, mm], 1); ab = np.linalg.lstsq(A, r, rcond=None)[0]
    rf = (ref - v["final"])[g]; cf = (v["lstm"] - v["final"])[g]
    gam = float(cf @ rf / (cf @ cf))
    print(f"val fits: alpha {alpha:.3f}  beta(offset) {beta:.3f}  (a,b) {ab[0]:.3f},{ab[1]:.3f}  gamma(final) {gam:.3f}  "
          f"mean c on gate {cc.mean()*1e3:+.2f} mm, ref-fm {r.mean()*1e3:+.2f} mm, ref-final {rf.mean()*1e3:+.2f} mm, ref-lstm {(r-cc).mean()*1e3:+.2f}")
    return dict(alpha=alpha, beta=beta, a2=float(ab[0]), b2=float(ab[1]), gamma=gam)


def variants(d, p):
    m, c, mu = parts(d)
    fm, fin = d["fm"], d["final"]
    return {"raw": d["lq"], "unet": fin, "fm": fm, "lstm": d["lstm"],
            "zm": fm + c - mu, "zmf": fm + c - frame_mean(d, c, np.isfinite(d["lq"])), "beta": fm + c - mu + p["beta"] * mu, "alpha": fm + p["alpha"] * c,
            "ab": fm + p["a2"] * (c - mu) + p["b2"] * mu, "gamma": fin + p["gamma"] * (d["lstm"] - fin)}


def scores(d, outs):
    t, lq, roi = d["truth"], d["lq"], d["roi"]
    F = len(t)
    res = {k: np.full((2, F), np.nan) for k in outs}
    for i in range(F):
        base = roi[i] & np.isfinite(lq[i]) & np.isfinite(t[i])
        mov = None
        if i > 0:
            mov = np.isfinite(t[i - 1]) & (np.abs(t[i] - np.nan_to_num(t[i - 1])) > 0.01) & (t[i] > 0) & (t[i - 1] > 0)
        for k, o in outs.items():
            e = (o[i][base].astype(np.float64) - t[i][base]) * 1e3
            res[k][0, i] = np.mean(e * e)
            if mov is not None and (base & mov).any():
                e = (o[i][base & mov].astype(np.float64) - t[i][base & mov]) * 1e3
                res[k][1, i] = np.mean(e * e)
    return res


def paired(a, b):
    d = (a - b); d = d[np.isfinite(d)]
    rng = np.random.default_rng(0)
    boots = d[rng.integers(0, len(d), (2000, len(d)))].mean(axis=1)
    return d.mean(), np.percentile(boots, 2.5), np.percentile(boots, 97.5)


if __name__ == "__main__":
    p = fit(load(sys.argv[1]))
    for s in sys.argv[2:]:
        d = load(s)
        res = scores(d, variants(d, p))
        print(s, "MSE all / moving:", "  ".join(f"{k} {np.nanmean(v[0]):.2f}/{np.nanmean(v[1]):.2f}" for k, v in res.items()))
        for k in res:
            if k in ("raw", "unet"):
                continue
            a = paired(res[k][1], res["unet"][1]); b = paired(res[k][0], res["unet"][0])
            print(f"   {k:6s} - unet moving {a[0]:+.2f} [{a[1]:+.2f}, {a[2]:+.2f}]   all {b[0]:+.2f} [{b[1]:+.2f}, {b[2]:+.2f}]")
