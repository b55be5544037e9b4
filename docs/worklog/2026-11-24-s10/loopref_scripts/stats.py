"""loopref: table from res.jsonl: per effect kind, sessions (seed 4001 = choice, excluded unless --all)."""
import json, sys
import numpy as np
rows = [json.loads(l) for l in open(sys.argv[1])]
allseeds = "--all" in sys.argv
kinds = {}
for r in rows:
    name = r["session"].split("/")[-1]
    kind, seed = name.split("_")
    if seed == "4001" and not allseeds and kind != "dr":
        continue
    kinds.setdefault(kind, {})[seed] = r  # last one wins
rng = np.random.default_rng(0)
def boot(v, n=4000):
    v = np.asarray(v); m = v[rng.integers(0, v.size, (n, v.size))].mean(1)
    return v.mean(), np.percentile(m, 2.5), np.percentile(m, 97.5)
ax = ["x mm", "y mm", "z mm", "rot deg"]
for kind, d in kinds.items():
    print(f"\n## {kind}: seeds {sorted(d)}")
    for s, r in sorted(d.items()):
        print(s, "found", r["sift"]["found"], "| refined_fit:", r["refine"]["refined_fit"])
        print("   sift  ", np.round(r["sift"]["err"], 3), {k: (round(v[0][next(iter(v[0]))], 4), round(v[1][next(iter(v[1]))], 4)) for k, v in r["sift"]["params"].items()}, "drift", round(r["sift"]["drift_ppm"], 1))
        print("   refine", np.round(r["refine"]["err"], 3), {k: (round(v[0][next(iter(v[0]))], 4), round(v[1][next(iter(v[1]))], 4)) for k, v in r["refine"]["params"].items()}, "drift", round(r["refine"]["drift_ppm"], 1))
    b = np.array([r["sift"]["err"] for r in d.values()]); a = np.array([r["refine"]["err"] for r in d.values()])
    for i, n in enumerate(ax):
        mb, ma, dd = boot(b[:, i]), boot(a[:, i]), boot(np.abs(a[:, i]) - np.abs(b[:, i]))
        print(f"   {n}: before {mb[0]:+.3f} [{mb[1]:+.3f},{mb[2]:+.3f}]  after {ma[0]:+.3f} [{ma[1]:+.3f},{ma[2]:+.3f}]  |after|-|before| {dd[0]:+.3f} [{dd[1]:+.3f},{dd[2]:+.3f}]")
print("\n## time shift error (us), fitted - truth.time_shift_us (drift sessions: the fitted shift is at the loop's t0)")
for kind, d in kinds.items():
    e = []
    for s, r in sorted(d.items()):
        ts = json.load(open(r["session"] + "/truth/truth.json"))["time_shift_us"]
        e.append((r["sift"]["shift_us"] - ts, r["refine"]["shift_us"] - ts))
    e = np.array(e)
    dd = boot(np.abs(e[:, 1]) - np.abs(e[:, 0]))
    print(kind, "before", np.round(e[:, 0]).tolist(), "after", np.round(e[:, 1]).tolist(),
          f"mean|.| {np.abs(e[:, 0]).mean():.0f} -> {np.abs(e[:, 1]).mean():.0f}; |after|-|before| {dd[0]:+.0f} [{dd[1]:+.0f},{dd[2]:+.0f}]")
