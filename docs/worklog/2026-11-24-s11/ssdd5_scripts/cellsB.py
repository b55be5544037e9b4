"""cellsB.py SESSIONS SEEDS: B's LSTM (level1_input = "final") - A's UNet, A's LSTM - A's UNet, B - A LSTM; moving and
all pixels, truth_roi, paired per frame; mean over seeds with a t interval across seeds."""
import sys
import numpy as np
import pandas as pd
from scipy import stats
sys.path.insert(0, ".")
from bench.truth_roi import with_truth_roi
from perf.ssdd_paired import paired

def table(path, metric):
    df = with_truth_roi(pd.read_parquet(path + "/results.parquet"))
    df = df[(df.reference == "truth_roi") & (df.metric == metric) & df.bin_lo_m.isna()]
    return df.pivot_table(index=["dataset", "frame"], columns="method", values="value")

f = lambda r: "%+.2f [%+.2f, %+.2f]" % r[:3]
for S in sys.argv[1].split(","):
    acc = []
    for s in sys.argv[2].split(","):
        row = []
        line = f"session {S} seed {s}:"
        for metric in ("mse_moving_mm2", "mse_mm2"):
            a, b = table(f"/tmp/ssdd5/R_A{s}_{S}", metric), table(f"/tmp/ssdd5/R_B{s}_{S}", metric)
            t = pd.concat({"unet": a.ssdd_unet, "A": a.ssdd_lstm, "B": b.ssdd_lstm}, axis=1)
            pb, pa = paired(t, "B", "unet"), paired(t, "A", "unet")
            row += [pb[0], pa[0]]
            line += f" {metric}: B-UNet {f(pb)} A-UNet {f(pa)} B-A {f(paired(t, 'B', 'A'))} |"
        acc.append(row); print(line)
    m = np.array(acc)
    for j, name in enumerate(("B-UNet moving", "A-UNet moving", "B-UNet all", "A-UNet all")):
        x = m[:, j]; h = stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x))
        print(f"session {S} mean over seeds {name}: {x.mean():+.2f} [{x.mean()-h:+.2f}, {x.mean()+h:+.2f}]  worst {x.max():+.2f}")
