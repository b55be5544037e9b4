"""cstat.py NPZ...: level 2's correction c = lstm - fold mean (mm): mean over ROI / outside ROI (pixels with LQ depth),
ROI fraction, and ref - fm / truth - fm means over the ROI"""
import sys, numpy as np
for p in sys.argv[1:]:
    z = np.load(p); lq = z["lq"]; roi = z["roi"]; c = (z["lstm"] - z["fm"]) * 1e3; v = np.isfinite(lq)
    t = z["truth"]; r = z["ref"]
    def mean(a, m): return np.nanmean(np.where(m, a, np.nan))
    print(p, f"c roi {mean(c, v & roi):+.2f} out {mean(c, v & ~roi):+.2f} median all {np.median(c[v]):+.2f} roi frac {(v&roi).sum()/v.sum():.2f}",
          f"truth-fm roi {mean((t - z['fm'])*1e3, v & roi & np.isfinite(t)):+.2f} ref-fm roi {mean((r - z['fm'])*1e3, v & roi & np.isfinite(r)):+.2f}"
          f" truth-final roi {mean((t - z['final'])*1e3, v & roi & np.isfinite(t)):+.2f}  ref-truth roi {mean((r-t)*1e3, v&roi&np.isfinite(r)&np.isfinite(t)):+.2f}")
