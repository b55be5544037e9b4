"""Paired per-frame differences (width 16 - width 8) of one method between two bench results on the same frames,
with 95 % bootstrap intervals (perf/ssdd_paired.py's statistic), against the truth on every ROI pixel.

    python width_paired.py R8/results.parquet R16/results.parquet
"""
import sys
import pandas as pd
sys.path.insert(0, "perf")
from ssdd_paired import paired
from bench.truth_roi import TRUTH_ROI, with_truth_roi


def table(path, metric):
    df = with_truth_roi(pd.read_parquet(path))
    df = df[(df["reference"] == TRUTH_ROI) & (df["metric"] == metric) & df["bin_lo_m"].isna()]
    return df.pivot_table(index=["dataset", "frame"], columns="method", values="value")


for metric in ("mse_mm2", "mse_moving_mm2"):
    a, b = table(sys.argv[1], metric), table(sys.argv[2], metric)
    for m in ("ssdd_unet", "ssdd_lstm"):
        v = pd.DataFrame({"w16": b[m], "w8": a[m]})
        d, lo, hi, n = paired(v, "w16", "w8")
        print(f"{metric:>15} {m:>9}: w8 {a[m].mean():7.2f} w16 {b[m].mean():7.2f}  w16 - w8 {d:+.2f} [{lo:+.2f}, {hi:+.2f}] (n={n})")
    v = pd.DataFrame({"lstm": b["ssdd_lstm"], "unet": b["ssdd_unet"]})
    d, lo, hi, n = paired(v, "lstm", "unet")
    print(f"{metric:>15} w16 lstm - unet {d:+.2f} [{lo:+.2f}, {hi:+.2f}]; bilateral {b['bilateral'].mean():.2f}")
