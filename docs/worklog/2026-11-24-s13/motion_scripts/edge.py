import numpy as np
z = np.load("/work/notes/motion/diag.npz")
bad = z["bad"]
for r in range(285, 350, 5):
    cols = np.nonzero(bad[r])[0]
    if not cols.size: continue
    c = cols[0]
    seg = slice(c - 8, c + 8)
    print(r, "bad cols", cols.min(), cols.max())
    for k in ("wto", "truth", "wtx", "plain", "ref"):
        print(f"   {k:6s}", " ".join(f"{x:4.1f}" if np.isfinite(x) else "  . " for x in z[k][r, seg]))
