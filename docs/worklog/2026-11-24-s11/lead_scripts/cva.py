"""cva.py SESSIONS SEEDS: per (seed, session) cell, C - A (paired per frame, truth_roi, moving pixels) for ssdd_unet and
ssdd_lstm, LSTM - UNet for each, then means over cells with t intervals (cells and seeds)."""
import sys
import numpy as np
import pandas as pd
from scipy import stats
sys.path.insert(0, ".")
from bench.truth_roi import with_truth_roi
from perf.ssdd_paired import paired

def table(path, metric="mse_moving_mm2"):
    df = with_truth_roi(pd.read_parquet(path + "/results.parquet"))
    df = df[(df.reference == "truth_roi") & (df.metric == metric) & df.bin_lo_m.isna()]
    return df.pivot_table(index=["dataset", "frame"], columns="method", values="value")

def tint(x):
    x = np.asarray(x); h = stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x))
    return "%+.2f [%+.2f, %+.2f]" % (x.mean(), x.mean() - h, x.mean() + h)

f = lambda r: "%+.2f [%+.2f, %+.2f]" % r[:3]
sessions = [int(x) for x in sys.argv[1].split(",")]; seeds = [int(x) for x in sys.argv[2].split(",")]
rows = []
for S in sessions:
    for s in seeds:
        c, a = table(f"/tmp/lead11/R_C{s}_{S}"), table(f"/tmp/lead11/R_A{s}_{S}")
        u = pd.concat({"cu": c.ssdd_unet, "au": a.ssdd_unet, "cl": c.ssdd_lstm, "al": a.ssdd_lstm, "cb": c.bilateral}, axis=1)
        du, dl = paired(u, "cu", "au"), paired(u, "cl", "al")
        oc, oa = paired(u, "cl", "cu"), paired(u, "al", "au")
        ub = paired(u, "cu", "cb")
        print(f"session {S} seed {s}: UNet C-A {f(du)} LSTM C-A {f(dl)} | LSTM-UNet C {f(oc)} A {f(oa)} | UNet-BF C {f(ub)}"
              f" | UNet C {u.cu.mean():.2f} A {u.au.mean():.2f} LSTM C {u.cl.mean():.2f} A {u.al.mean():.2f}")
        rows.append(dict(S=S, s=s, du=du[0], dl=dl[0], oc=oc[0], oa=oa[0]))
r = pd.DataFrame(rows)
print("over cells: UNet C-A", tint(r.du), " LSTM C-A", tint(r.dl), " LSTM-UNet C", tint(r.oc), " A", tint(r.oa))
g = r.groupby("s").mean(numeric_only=True)
print("over seeds (session means): UNet C-A", tint(g.du), " LSTM C-A", tint(g.dl), " LSTM-UNet C", tint(g.oc), " A", tint(g.oa))
print("cells with LSTM-UNet > 0: C", int((r.oc > 0).sum()), " A", int((r.oa > 0).sum()), "of", len(r))
