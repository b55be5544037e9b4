"""tidy2: coverage of the loop's pose sd at the three stages (the fit's covariance; + the shift's shared error;
+ POSE_MODEL_ERROR 0.26 mm / 0.005 deg) and of the base fit's covariance for the loop's pose (what aligned.json
reported before), per axis, 3D translation ellipsoid (chi2_3 95 %), RMS error/sd; and aligned.json's scalar
translation_mm. usage: stages.py NAME FILE.jsonl... (loopcov.py output)"""
import json, sys
import numpy as np
FLOOR = np.diag([np.radians(0.005) ** 2] * 3 + [0.26e-3 ** 2] * 3)
recs = []
for f in sys.argv[2:]:
    for l in open(f):
        r = json.loads(l)
        if not r["changed"]:
            continue
        C = np.array(r["cov"])
        if r.get("cov_shared"):  # written by the code of 3429f93 (the shift's term only)
            S = np.array(r["cov_shared"])
        else:
            A = np.array(r["A_inv"]); g = A[:, 6] / A[6, 6]; S = np.outer(g, g)[:7, :7] * 0.16
        recs.append((np.array(r["err"]), C[:6, :6], S[:6, :6], np.array(r["base_cov"])))
stages = (("fit covariance (before)", lambda C, S, B: C), ("+ shift's shared error", lambda C, S, B: C + S),
          ("+ pose floor (now)", lambda C, S, B: C + S + FLOOR), ("base fit's cov (aligned.json before)", lambda C, S, B: B))
for lab, f in stages:
    zs, n3, sc = [], 0, []
    for e, C, S, B in recs:
        V = f(C, S, B)
        n3 += int(e[3:] @ np.linalg.solve(V[3:, 3:], e[3:]) < 7.815)
        zs.append(e / np.sqrt(np.diag(V)))
        sc.append(1e3 * np.sqrt(np.trace(V[3:, 3:])))
    zs = np.array(zs)
    print(f"{sys.argv[1]} | {lab} | " + " | ".join(map(str, (np.abs(zs) < 1.96).sum(0))) + f" | {n3} of {len(recs)} | "
          + ", ".join(f"{v:.2f}" for v in np.sqrt((zs ** 2).mean(0))[3:]) + f" | translation_mm median {np.median(sc):.2f}")
err = [1e3 * np.linalg.norm(e[3:]) for e, *_ in recs]
print(f"{sys.argv[1]}: median translation error {np.median(err):.2f} mm")
