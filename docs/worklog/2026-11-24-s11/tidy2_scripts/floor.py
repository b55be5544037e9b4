"""tidy2: a session-wide pose error floor for the loop's pose (isotropic: sd_t on each translation axis, sd_r on each
rotation axis, in quadrature with cov + cov_shared), chosen so that RMS error/sd over the three axes is 1 on the
files given first (design), then coverage on the others (held out). usage: floor.py DESIGN.jsonl -- HELDOUT.jsonl..."""
import json, sys
import numpy as np
from scipy.optimize import brentq
args = sys.argv[1:]
cut = args.index("--")
def load(files):
    out = []
    for f in files:
        for l in open(f):
            r = json.loads(l)
            if not r["changed"]:
                continue
            C = np.array(r["cov"])
            if r.get("cov_shared"):
                C = C + np.array(r["cov_shared"])
            else:
                A = np.array(r["A_inv"]); g = A[:, 6] / A[6, 6]; C = C + np.outer(g, g)[:7, :7] * 0.16
            out.append((np.array(r["err"]), np.diag(C)[:6]))
    return out
design, held = load(args[:cut]), load(args[cut + 1:])
def rms(recs, sl, f):
    z = [e[sl] / np.sqrt(v[sl] + f ** 2) for e, v in recs]
    return float(np.sqrt(np.mean(np.square(z))))
import os
sd_t = brentq(lambda f: rms(design, slice(3, 6), f) - 1, 0, 0.01) if rms(design, slice(3, 6), 0) > 1 else 0.0
sd_r = brentq(lambda f: rms(design, slice(0, 3), f) - 1, 0, 0.01) if rms(design, slice(0, 3), 0) > 1 else 0.0
print(f"design n={len(design)}: sd_t {1e3 * sd_t:.3f} mm, sd_r {np.degrees(sd_r):.4f} deg")
for name, recs in (("design", design), ("held out", held)):
    for lab, ft, fr in (("without", 0, 0), ("with", sd_t, sd_r)):
        z = np.array([e / np.sqrt(v + np.r_[[fr ** 2] * 3, [ft ** 2] * 3]) for e, v in recs])
        cover = (np.abs(z) < 1.96).sum(0)
        print(f"{name:8s} {lab:7s} n={len(recs)} cover " + " ".join(map(str, cover)) + "  RMS z " + " ".join(f"{v:.2f}" for v in np.sqrt((z ** 2).mean(0))))
if os.environ.get("FLOOR"):  # the rounded values the code uses, e.g. FLOOR=0.26e-3,0.005
    ft, fr_deg = (float(v) for v in os.environ["FLOOR"].split(","))
    for name, recs in (("design", design), ("held out", held)):
        z = np.array([e / np.sqrt(v + np.r_[[np.radians(fr_deg) ** 2] * 3, [ft ** 2] * 3]) for e, v in recs])
        print(f"{name:8s} FLOOR   n={len(recs)} cover " + " ".join(map(str, (np.abs(z) < 1.96).sum(0))) + "  RMS z "
              + " ".join(f"{v:.2f}" for v in np.sqrt((z ** 2).mean(0))))
