"""Coverage table of extr_cov.py's records: python coverage.py FILE.jsonl..."""
import json, sys
import numpy as np
recs = [json.loads(l) for f in sys.argv[1:] for l in open(f)]
V = {"naive (every pair independent; before)": ["naive"],
     "cluster-robust, probe x HQ cell, no shift term": ["probe x cell"],
     "**cluster-robust, probe x HQ cell + shift term (reported now)**": ["reported"]}
print(f"{len(recs)} sessions: seeds {', '.join(str(r['seed']) for r in recs)}\n")
print("| covariance | r_x | r_y | r_z | t_x | t_y | t_z | translation, 3D (chi2_3 95 %) | RMS z (t_x, t_y, t_z) |")
print("|---|---|---|---|---|---|---|---|---|")
for name, parts in V.items():
    Z, M = [], []
    for r in recs:
        C = sum(np.array(r["covs"][p]) for p in parts)
        d = np.array(r["err"])
        Z.append(d / np.sqrt(np.diag(C)))
        M.append(d[3:] @ np.linalg.solve(C[3:, 3:], d[3:]))
    Z, M = np.array(Z), np.array(M)
    cov = (np.abs(Z) < 1.96).mean(axis=0)
    n = len(recs)
    cells = [f"{int(round(c * n))}/{n}" for c in cov]
    rms = np.sqrt((Z[:, 3:] ** 2).mean(axis=0))
    print(f"| {name} | " + " | ".join(cells) + f" | {int((M < 7.815).sum())}/{n} | " + ", ".join(f"{x:.2f}" for x in rms) + " |")
sd = lambda parts: np.array([np.sqrt(np.diag(sum(np.array(r["covs"][p]) for p in parts)))[3:] * 1e3 for r in recs])
e = np.array([np.array(r["err"])[3:] * 1e3 for r in recs])
print(f"\nmean |error| mm (x, y, z): {np.round(np.abs(e).mean(0), 2)}; RMS error: {np.round(np.sqrt((e**2).mean(0)), 2)}")
print(f"mean sd mm before (naive): {np.round(sd(['naive']).mean(0), 2)}; after: {np.round(sd(['reported']).mean(0), 2)}")
sh = np.array([(r['shift_us'] - r['shift_true_us']) / r['shift_std_us'] for r in recs])
print(f"time shift error / its sd: RMS {np.sqrt((sh**2).mean()):.2f}, within 1.96: {(np.abs(sh) < 1.96).sum()}/{len(sh)}")
