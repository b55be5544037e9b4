"""cells.py TAG SESSIONS SEEDS: per (seed, session) cell, paired per frame (perf/ssdd_paired.paired, truth_roi):
LSTM - UNet on moving pixels and on all pixels, UNet - BF and UNet - raw (moving), for run TAG (results dirs
/tmp/ssdd5/R_{TAG}{seed}_{session}, or for TAG=L the baselines /tmp/s4/R_L{seed}_{S} / /tmp/v10/R_{seed}_{S} /
/tmp/ssdd5/R_L{seed}_{S}); with a second TAG after a colon (A:L) also A's LSTM - L's LSTM (same level 1).
Then the mean over seeds per session with a t interval across seeds."""
import os
import sys
import numpy as np
import pandas as pd
from scipy import stats
sys.path.insert(0, ".")
from bench.truth_roi import with_truth_roi
from perf.ssdd_paired import paired

def rdir(tag, s, S):
    if tag == "L":
        for p in (f"/tmp/ssdd5/R_L{s}_{S}", f"/tmp/s4/R_L{s}_{S}", f"/tmp/v10/R_{s}_{S}"):
            if os.path.exists(p + "/results.parquet"):
                return p
    return f"/tmp/ssdd5/R_{tag}{s}_{S}"

def table(path, metric):
    df = with_truth_roi(pd.read_parquet(path + "/results.parquet"))
    df = df[(df.reference == "truth_roi") & (df.metric == metric) & df.bin_lo_m.isna()]
    return df.pivot_table(index=["dataset", "frame"], columns="method", values="value")

tags = sys.argv[1].split(":")
sessions = [int(x) for x in sys.argv[2].split(",")]
seeds = [int(x) for x in sys.argv[3].split(",")]
f = lambda r: "%+.2f [%+.2f, %+.2f]" % r[:3]
summ = {}
for S in sessions:
    for s in seeds:
        t = table(rdir(tags[0], s, S), "mse_moving_mm2"); ta = table(rdir(tags[0], s, S), "mse_mm2")
        lm, la = paired(t, "ssdd_lstm", "ssdd_unet"), paired(ta, "ssdd_lstm", "ssdd_unet")
        line = (f"{tags[0]} session {S} seed {s}: LSTM-UNet moving {f(lm)} all {f(la)} | UNet-BF moving "
                f"{f(paired(t, 'ssdd_unet', 'bilateral'))} UNet-raw moving {f(paired(t, 'ssdd_unet', 'raw'))}"
                f" | UNet {t.ssdd_unet.mean():.2f} LSTM {t.ssdd_lstm.mean():.2f}")
        summ.setdefault(S, []).append((lm[0], la[0]))
        if len(tags) > 1:
            b, ba = table(rdir(tags[1], s, S), "mse_moving_mm2"), table(rdir(tags[1], s, S), "mse_mm2")
            u = pd.concat({"a": t.ssdd_lstm, "b": b.ssdd_lstm, "ua": t.ssdd_unet, "ub": b.ssdd_unet}, axis=1)
            ua = pd.concat({"a": ta.ssdd_lstm, "b": ba.ssdd_lstm}, axis=1)
            line += (f" | LSTM {tags[0]}-{tags[1]} moving {f(paired(u, 'a', 'b'))} all {f(paired(ua, 'a', 'b'))}"
                     f" (UNet same: {float((u.ua - u.ub).abs().max()):.2g})")
        print(line)
allm = []
for S, v in summ.items():
    m = np.array(v); allm.append(m)
    for j, name in enumerate(("moving", "all")):
        x = m[:, j]; h = stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x))
        print(f"{tags[0]} session {S} mean over seeds {seeds} LSTM-UNet {name}: {x.mean():+.2f} [{x.mean()-h:+.2f}, {x.mean()+h:+.2f}]")
