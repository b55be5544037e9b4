"""Per-seed gap (flow reference MAE at 7 ms minus the synchronous twin's) from motion_rule.sh's dumps, new vs old code.
python fg_table.py SEEDS_NEW SEEDS_OLD   (e.g. 1-24 1-18); reads /tmp/recheck/fg_{new,old}_p{7,0}_sS.json"""
import json, sys
import numpy as np

def mae(tag, p, s):
    try:
        r = list(json.load(open(f"/tmp/recheck/fg_{tag}_p{p}_s{s}.json")).values())[0]
    except FileNotFoundError:
        return None, None
    return sum(x["flow_sum"] for x in r) / sum(x["flow_n"] for x in r), 100 * sum(x["masked"] for x in r) / sum(x["roi_n"] for x in r)

rng = lambda a: range(int(a.split("-")[0]), int(a.split("-")[1]) + 1)
print("| seed | new: flow / sync / gap, masked % (7 ms) | old (371b651): flow / sync / gap, masked % |")
print("|---|---|---|")
gn, go = [], []
for s in rng(sys.argv[1]):
    n7, m7 = mae("new", 7, s); n0, _ = mae("new", 0, s); o7, om = mae("old", 7, s); o0, _ = mae("old", 0, s)
    a = f"{n7:.2f} / {n0:.2f} / **{n7 - n0:.2f}**, {m7:.2f}" if n7 is not None and n0 is not None else "-"
    b = f"{o7:.2f} / {o0:.2f} / {o7 - o0:.2f}, {om:.2f}" if o7 is not None and o0 is not None else "-"
    if n7 is not None and n0 is not None: gn.append(n7 - n0)
    if o7 is not None and o0 is not None: go.append(o7 - o0)
    print(f"| {s} | {a} | {b} |")
gn, go = np.array(gn), np.array(go)
print(f"\nnew: {np.sum(gn <= 2)} of {gn.size} within 2 mm (mean gap {gn.mean():.2f}); old: {np.sum(go <= 2)} of {go.size} (mean {go.mean():.2f}); "
      f"new on the old's seeds: {np.sum(gn[:go.size] <= 2)} of {go.size}")
