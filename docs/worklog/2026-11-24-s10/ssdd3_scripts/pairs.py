"""pairs.py SESSION SEED: LSTM (landed L, offset O) - UNet, and UNet - raw / BF, from the bench's results of
R_L<seed>_<session> and R_O<seed>_<session> merged (O's ssdd_lstm renamed ssdd_lstm_off), with perf/ssdd_paired.py's
statistic (two decimals), truth_roi reference."""
import sys
import pandas as pd
sys.path.insert(0, "/work/wt/ssdd3/perf")
from ssdd_paired import paired
from bench.truth_roi import with_truth_roi
s, seed = sys.argv[1], sys.argv[2]
a = pd.read_parquet(f"/tmp/s3/R_L{seed}_{s}/results.parquet")
b = pd.read_parquet(f"/tmp/s3/R_O{seed}_{s}/results.parquet")
b = b[b.method == "ssdd_lstm"].assign(method="ssdd_lstm_off")
merged = pd.concat([a, b], ignore_index=True)
merged.to_parquet(f"/tmp/s3/M_{seed}_{s}.parquet")      # for perf/ssdd_paired.py itself
df = with_truth_roi(merged)
out = []
for metric in ("mse_moving_mm2", "mse_mm2"):
    d = df[(df.reference == "truth_roi") & (df.metric == metric) & df.bin_lo_m.isna()]
    t = d.pivot_table(index=["dataset", "frame"], columns="method", values="value")
    means = " ".join(f"{m} {t[m].mean():.2f}" for m in t)
    print(f"{s} seed {seed} {metric}: {means}")
    for x, y in (("ssdd_lstm", "ssdd_unet"), ("ssdd_lstm_off", "ssdd_unet"), ("ssdd_lstm_off", "ssdd_lstm"),
                 ("ssdd_unet", "raw"), ("ssdd_unet", "bilateral")):
        m, lo, hi, n = paired(t, x, y)
        print(f"   {x} - {y}: {m:+.2f} [{lo:+.2f}, {hi:+.2f}] n={n}")
