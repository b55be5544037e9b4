"""fm_vs_final.py SESSION SEED: level 2 (offset = "level1") fed the fold models' mean (O) against fed the final level 1
(F, same level-2 weights), truth_roi, moving and all pixels, paired bootstrap (perf/ssdd_paired.py's statistic)."""
import sys
import pandas as pd
sys.path.insert(0, "/work/wt/ssdd3/perf")
from ssdd_paired import paired
from bench.truth_roi import with_truth_roi
s, seed = sys.argv[1], sys.argv[2]
a = pd.read_parquet(f"/tmp/s3/R_L{seed}_{s}/results.parquet")
o = pd.read_parquet(f"/tmp/s3/R_O{seed}_{s}/results.parquet").assign(method="lstm_fold_mean")
f = pd.read_parquet(f"/tmp/s3/R_F{seed}_{s}/results.parquet").assign(method="lstm_final")
df = with_truth_roi(pd.concat([a[a.method == "ssdd_unet"], o, f], ignore_index=True))
for metric in ("mse_moving_mm2", "mse_mm2"):
    d = df[(df.reference == "truth_roi") & (df.metric == metric) & df.bin_lo_m.isna()]
    t = d.pivot_table(index=["dataset", "frame"], columns="method", values="value")
    print(f"{s} seed {seed} {metric}: " + " ".join(f"{m} {t[m].mean():.2f}" for m in t))
    for x, y in (("lstm_fold_mean", "lstm_final"), ("lstm_final", "ssdd_unet"), ("lstm_fold_mean", "ssdd_unet")):
        m, lo, hi, n = paired(t, x, y)
        print(f"   {x} - {y}: {m:+.2f} [{lo:+.2f}, {hi:+.2f}] n={n}")
