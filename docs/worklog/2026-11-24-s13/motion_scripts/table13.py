"""Per-seed table, session 13 motion: strict (acc.py) and footprint-fg (acc_rule.py ROI=rule), this checkout ("new")
against main ("main", session 12's code), gaps to the synchronous twin with 95 % bootstrap intervals over pairs.
python table13.py SEEDS (e.g. 1-18 or 25-36)"""
import json, sys, os
import numpy as np
a, b = sys.argv[1].split("-"); seeds = range(int(a), int(b) + 1)
rng = np.random.default_rng(13); D = 5000
def load(path):
    if not os.path.exists(path): return None
    return list(json.load(open(path)).values())[0]
def arr(r): return np.array([x["flow_sum"] for x in r]), np.array([x["flow_n"] for x in r], float)
def mae(r): s, n = arr(r); return s.sum() / n.sum()
def boot(r):
    s, n = arr(r); idx = rng.integers(0, len(s), (D, len(s))); return s[idx].sum(-1) / n[idx].sum(-1)
def gap(r7, r0):
    g = boot(r7) - boot(r0); return mae(r7) - mae(r0), np.percentile(g, 2.5), np.percentile(g, 97.5)
def paired(rn, rm):
    sn, nn = arr(rn); sm, nm = arr(rm); idx = rng.integers(0, len(sn), (D, len(sn)))
    d = sn[idx].sum(-1) / nn[idx].sum(-1) - sm[idx].sum(-1) / nm[idx].sum(-1)
    return mae(rn) - mae(rm), np.percentile(d, 2.5), np.percentile(d, 97.5)
M, O = "/tmp/recheck/m", "/tmp/motion"
print("| seed | strict: main 7 ms | **new 7 ms** / sync / **gap [95 %]** | new − main, paired [95 %] | net lost % | "
      "footprint-fg: main gap | **new 7 ms / sync / gap [95 %]** | fg masked % (new) |")
print("|---|---|---|---|---|---|---|---|")
G = {"strict": [], "fg": []}; pooled = []
for s in seeds:
    m7, m0 = load(f"{M}/acc_p7_s{s}.json"), load(f"{M}/acc_p0_s{s}.json")
    n7, n0 = load(f"{O}/s13_acc_p7_s{s}.json"), load(f"{O}/s13_acc_p0_s{s}.json")
    f7, f0 = load(f"{O}/s13_fg_p7_s{s}.json"), load(f"{O}/s13_fg_p0_s{s}.json")
    fm7 = load(f"/tmp/recheck/fg_new_p7_s{s}.json") or load(f"{O}/main_fg_p7_s{s}.json")
    fm0 = load(f"/tmp/recheck/fg_new_p0_s{s}.json") or load(f"{O}/main_fg_p0_s{s}.json")
    if n7 is None or n0 is None: continue
    g = gap(n7, n0); p = paired(n7, m7); G["strict"].append(g[0]); pooled.append((n7, m7))
    lost = 100 * sum(r["lost"] for r in n7) / sum(r["plain_n"] for r in n7)
    row = (f"| {s} | {mae(m7):.2f} | {mae(n7):.2f} / {mae(n0):.2f} / **{g[0]:.2f}** [{g[1]:.2f}, {g[2]:.2f}] | "
           f"{p[0]:+.2f} [{p[1]:+.2f}, {p[2]:+.2f}] | {lost:.2f} | ")
    if f7 is not None and f0 is not None:
        fg = gap(f7, f0); G["fg"].append(fg[0])
        mk = 100 * sum(r["masked"] for r in f7) / sum(r["roi_n"] for r in f7)
        mg = f"{mae(fm7) - mae(fm0):.2f}" if fm7 is not None and fm0 is not None else "-"
        row += f"{mg} | {mae(f7):.2f} / {mae(f0):.2f} / **{fg[0]:.2f}** [{fg[1]:.2f}, {fg[2]:.2f}] | {mk:.2f} |"
    else:
        row += "- | - | - |"
    print(row)
for k, v in G.items():
    v = np.array(v)
    if v.size: print(f"\n{k}: {np.sum(v <= 2)} of {v.size} seeds within 2 mm; gaps {v.min():.2f}-{v.max():.2f}, mean {v.mean():.2f}")
tn = np.zeros(D); tm = np.zeros(D); nn_ = np.zeros(D); nm_ = np.zeros(D)
for rn, rm in pooled:
    sn, n1 = arr(rn); sm, n2 = arr(rm); idx = rng.integers(0, len(sn), (D, len(sn)))
    tn += sn[idx].sum(-1); nn_ += n1[idx].sum(-1); tm += sm[idx].sum(-1); nm_ += n2[idx].sum(-1)
N = sum(arr(r)[0].sum() for r, _ in pooled) / sum(arr(r)[1].sum() for r, _ in pooled)
Mm = sum(arr(r)[0].sum() for _, r in pooled) / sum(arr(r)[1].sum() for _, r in pooled)
d = tn / nn_ - tm / nm_
print(f"strict pooled, new − main (paired pairs, stratified by seed): {N:.3f} vs {Mm:.3f} mm, {N - Mm:+.3f} [{np.percentile(d, 2.5):+.3f}, {np.percentile(d, 97.5):+.3f}]")
