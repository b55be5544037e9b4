"""Per-seed rows of perf/loop_study.py JSONL against the same seed's clean session (session 12, recheck).

python table.py EFFECT.jsonl CLEAN.jsonl
For each row: what the loop added ("found"), the expected effect's estimate, 95 % interval, error %, whether the
interval covers the truth, and the held-out median |residual| after the loop over the clean session's (feature px,
and depth % where the loop has a depth phase), plus the stages' accepted names and each effect's look-alikes.
"""
import json
import sys

sys.path.insert(0, ".")
from perf.loop_study import EXPECT  # noqa: E402

rows = [json.loads(l) for l in open(sys.argv[1])]
clean = {r["seed"]: r for r in map(json.loads, open(sys.argv[2]))} if len(sys.argv) > 2 else {}
for r in rows:
    if r.get("failed"):
        print(f"seed {r['seed']}: failed before the loop: {r.get('failed')}")
        continue
    line = [f"seed {r['seed']}", f"found {sorted(r['found'])}"]
    for sim, v in r["effects"].items():
        name, param, conv = EXPECT.get(sim, (None, None, None))
        if name is None:
            continue
        t = conv(v)
        d = r["found"].get(name)
        if d is None:
            line.append(f"{name}: not named")
            continue
        est, iv = d["params"][param], (d.get("interval95") or {}).get(param)
        cov = iv is not None and iv[0] <= t <= iv[1]
        la = d.get("look_alikes") or d.get("lookalikes")
        line.append(f"{name}.{param} {est:.5g} [{iv[0]:.5g}, {iv[1]:.5g}] err {100 * (est - t) / t:+.1f} % covers {cov}"
                    + (f" look-alikes {la}" if la else ""))
    c = clean.get(r["seed"])
    hp = r["heldout_px"]
    s = f"held-out px {hp[0]:.4f}->{hp[1]:.4f}"
    if c:
        s += f" after/clean px {hp[1] / c['heldout_px'][1]:.3f}"
        if r["heldout_depth"] and c["heldout_depth"]:
            s += f", depth {r['heldout_depth'][1] / c['heldout_depth'][1]:.3f} ({100 * r['heldout_depth'][1]:.3f} % vs {100 * c['heldout_depth'][1]:.3f} %)"
    line.append(s)
    line.append(f"unexplained {r['unexplained']}")
    print(" | ".join(line))
