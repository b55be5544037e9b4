"""tidy2: coverage of variants of the loop's pose covariance (loopcov.py output): the fit's cluster-robust
covariance, plus the errors every row shares (the time shift's MODEL_ERROR_US; each accepted effect's model
error) carried into the pose through the fit's information: sum_k g_k g_k^T m_k^2, g_k = Sigma[:, k] / Sigma[k, k].
usage: covstat2.py FILE.jsonl..."""
import json, sys
import numpy as np
recs = [json.loads(l) for f in sys.argv[1:] for l in open(f)]
recs = [r for r in recs if r["changed"]]
names = ["r_x", "r_y", "r_z", "t_x", "t_y", "t_z"]
def shared(r, shift_us, effects):
    A = np.array(r["A_inv"]); m = np.zeros(A.shape[0]); m[6] = shift_us / 1000
    if effects:
        m[7:7 + len(r["model_err"])] = r["model_err"]
    G = A / np.diag(A)[None, :]
    return (G * m[None, :] ** 2) @ G.T
def table(label, get):
    z, e3 = [], []
    for r in recs:
        err, cov = get(r)
        z.append(err / np.sqrt(np.diag(cov)))
        e3.append(err[3:] @ np.linalg.solve(cov[3:, 3:], err[3:]))
    z = np.array(z)
    cover = (np.abs(z) < 1.96).sum(0)
    print(f"{label:34s} n={len(recs)} cover " + " ".join(f"{n}={c}" for n, c in zip(names, cover))
          + f" 3D={int((np.array(e3) < 7.815).sum())}  RMS z " + " ".join(f"{v:.2f}" for v in np.sqrt((z ** 2).mean(0))))
for lab, s, eff in (("fit only (before)", 0, False), ("+ shift 400 us", 400, False), ("+ shift 400 us + effects' errors", 400, True),
                    ("+ effects' errors only", 0, True)):
    table(lab, lambda r, s=s, eff=eff: (np.array(r["err"]), (np.array(r["cov"]) + shared(r, s, eff)[:7, :7])[:6, :6]))
table("base fit's own error and cov", lambda r: (np.array(r["base_err"]), np.array(r["base_cov"])))
table("loop's T, base cov (aligned.json before)", lambda r: (np.array(r["err"]), np.array(r["base_cov"])))
for r in recs:
    A = np.array(r["A_inv"])
    print(r["session"].split("/")[-1], r["names"][7:], r["model_err"])
if any(r.get("cov_shared") for r in recs):
    table("code: cov + cov_shared (aligned.json now)", lambda r: (np.array(r["err"]), (np.array(r["cov"]) + np.array(r["cov_shared"]))[:6, :6]))
