"""(session 12 recheck: a copy of 2026-11-24-s10/motion3_scripts/stats.py reading /tmp/recheck/m/.)
Seed table and paired bootstrap intervals from acc.py dumps.
python stats.py BASE.json VARIANT.json SYNC.json --seeds 4,6,7,8 [--draws 5000]
Per seed: variant MAE, synchronous MAE, gap (95 % bootstrap over pairs, each session resampled on its own), net lost %,
variant - base paired (same pairs). Pooled over the seeds: variant - base, paired, stratified by seed."""
import json, sys, argparse
import numpy as np
ap = argparse.ArgumentParser(); ap.add_argument("base"); ap.add_argument("var"); ap.add_argument("sync")
ap.add_argument("--seeds", required=True); ap.add_argument("--draws", type=int, default=5000); a = ap.parse_args()
B, V, S = (json.load(open(p)) for p in (a.base, a.var, a.sync))
seeds = [int(s) for s in a.seeds.split(",")]
rng = np.random.default_rng(12)
def arr(recs, k):
    return np.array([r[k + "_sum"] for r in recs]), np.array([r[k + "_n"] for r in recs])
def boot_mae(s, n, idx):
    return s[idx].sum(-1) / n[idx].sum(-1)
print("| seed | base MAE | variant MAE | synchronous | gap [95 %] | variant - base [95 %] | net lost % |")
print("|---|---|---|---|---|---|---|")
pooled_b, pooled_v = [], []
for sd in seeds:
    kb = f"/tmp/recheck/m/p7_s{sd}"; k0 = f"/tmp/recheck/m/p0_s{sd}"
    bs, bn = arr(B[kb], "flow"); vs, vn = arr(V[kb], "flow"); ss, sn = arr(S[k0], "flow")
    m = len(bs); idx = rng.integers(0, m, (a.draws, m)); idx0 = rng.integers(0, len(ss), (a.draws, len(ss)))
    gap = boot_mae(vs, vn, idx) - boot_mae(ss, sn, idx0)
    dif = boot_mae(vs, vn, idx) - boot_mae(bs, bn, idx)
    lost = 100 * sum(r["lost"] for r in V[kb]) / sum(r["plain_n"] for r in V[kb])
    g0 = vs.sum() / vn.sum() - ss.sum() / sn.sum(); d0 = vs.sum() / vn.sum() - bs.sum() / bn.sum()
    print(f"| {sd} | {bs.sum()/bn.sum():.2f} | {vs.sum()/vn.sum():.2f} | {ss.sum()/sn.sum():.2f} | {g0:.2f} "
          f"[{np.percentile(gap, 2.5):.2f}, {np.percentile(gap, 97.5):.2f}] | {d0:+.3f} [{np.percentile(dif, 2.5):+.3f}, "
          f"{np.percentile(dif, 97.5):+.3f}] | {lost:.2f} |")
    pooled_b.append((bs, bn)); pooled_v.append((vs, vn))
# pooled paired change, stratified: resample pairs within each seed
db, dv = np.zeros(a.draws), np.zeros(a.draws)
tb = np.zeros(a.draws); tn = np.zeros(a.draws); ub = np.zeros(a.draws); un = np.zeros(a.draws)
for (bs, bn), (vs, vn) in zip(pooled_b, pooled_v):
    idx = rng.integers(0, len(bs), (a.draws, len(bs)))
    tb += bs[idx].sum(-1); tn += bn[idx].sum(-1); ub += vs[idx].sum(-1); un += vn[idx].sum(-1)
d = ub / un - tb / tn
B0 = sum(b.sum() for b, _ in pooled_b) / sum(n.sum() for _, n in pooled_b)
V0 = sum(b.sum() for b, _ in pooled_v) / sum(n.sum() for _, n in pooled_v)
print(f"\npooled over seeds {a.seeds}: base {B0:.3f} mm, variant {V0:.3f} mm, variant - base {V0 - B0:+.3f} mm "
      f"[95 % {np.percentile(d, 2.5):+.3f}, {np.percentile(d, 97.5):+.3f}]")
