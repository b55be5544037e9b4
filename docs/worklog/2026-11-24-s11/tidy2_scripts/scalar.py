"""tidy2: aligned.json's T_lq_hq_std translation_mm (root of the covariance's translation trace) before (the base
fit's) and after (the loop's with the shared shift error), beside the translation error's norm, per session.
usage: scalar.py FILE.jsonl"""
import json, sys
import numpy as np
rows = []
for l in open(sys.argv[1]):
    r = json.loads(l)
    if not r["changed"]:
        continue
    e = 1e3 * np.linalg.norm(r["err"][3:6])
    before = 1e3 * np.sqrt(np.trace(np.array(r["base_cov"])[3:, 3:]))
    after = 1e3 * np.sqrt(np.trace((np.array(r["cov"]) + np.array(r["cov_shared"] or np.zeros((7, 7))))[3:6, 3:6]))
    rows.append((r["session"].split("/")[-1], e, before, after))
    print(f"{rows[-1][0]:8s} |t err| {e:.2f} mm  reported before {before:.2f}  after {after:.2f}")
a = np.array([x[1:] for x in rows])
print(f"median |t err| {np.median(a[:, 0]):.2f}; reported before median {np.median(a[:, 1]):.2f} (range {a[:, 1].min():.2f}-{a[:, 1].max():.2f}), "
      f"after {np.median(a[:, 2]):.2f} ({a[:, 2].min():.2f}-{a[:, 2].max():.2f}); |err| < 2 x reported: before {(a[:, 0] < 2 * a[:, 1]).sum()}, after {(a[:, 0] < 2 * a[:, 2]).sum()} of {len(a)}")
