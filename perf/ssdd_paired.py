"""Paired per-frame differences between leaderboard columns, with bootstrap intervals.

    .venv/bin/python perf/ssdd_paired.py RESULTS/results.parquet [--reference truth] [--metric mse_mm2]
        [--pairs ssdd_unet-raw,ssdd_unet-bilateral,ssdd_lstm-ssdd_unet]

``--reference``: ``hq`` (the warped HQ reference), ``truth`` (the simulator's truth on the HQ reference's
pixels: like with like with ``hq``; results schema 2 and later), ``truth_noref`` (the truth on the ROI
pixels without a reference: silhouettes / no reference) or ``truth_roi`` (the truth on every ROI pixel,
what ``truth`` meant before schema 2; derived exactly from the two strata by :mod:`bench.truth_roi`,
metrics n_valid, fill_rate, mse_mm2, rmse_mm, mae_mm, bias_mm and the moving ones only).

For each pair A-B: the mean over frames of (A - B) on the same frame (frames where both have a value),
and its 95 % bootstrap interval (2000 resamples of the frames, seed 0). The difference is significant
when the interval excludes 0. This is the statistic behind "ssdd_unet beats raw" in the notes: the
leaderboard's per-column intervals overlap more than paired differences do.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import pandas as pd

from bench.truth_roi import TRUTH_ROI, with_truth_roi


def paired(values: pd.DataFrame, a: str, b: str, *, resamples: int = 2000) -> tuple[float, float, float, int]:
    """``values``: frame x method table. Mean of ``a - b`` over common frames, 95 % bootstrap bounds, n."""
    d = (values[a] - values[b]).dropna().to_numpy()
    rng = np.random.default_rng(0)
    boots = d[rng.integers(0, len(d), (resamples, len(d)))].mean(axis=1)
    return float(d.mean()), float(np.percentile(boots, 2.5)), float(np.percentile(boots, 97.5)), len(d)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results")
    ap.add_argument("--reference", default="truth")
    ap.add_argument("--metric", default="mse_mm2")
    ap.add_argument("--pairs", default="ssdd_unet-raw,ssdd_unet-bilateral,ssdd_lstm-ssdd_unet")
    a = ap.parse_args()
    df = pd.read_parquet(a.results)
    if a.reference == TRUTH_ROI:
        df = with_truth_roi(df)
    df = df[(df.reference == a.reference) & (df.metric == a.metric) & df.bin_lo_m.isna()]
    table = df.pivot_table(index=["dataset", "frame"], columns="method", values="value")
    missing = sorted({m for pair in a.pairs.split(",") for m in pair.split("-")} - set(table.columns))
    if missing:
        print(f"{a.results}: no {a.metric} rows against reference {a.reference} for {', '.join(missing)}"
              + (" (truth_roi offers only the metrics that combine exactly across the strata)"
                 if a.reference == TRUTH_ROI else ""), file=sys.stderr)
        return 2
    print(f"{a.metric} vs {a.reference}: mean per frame " + ", ".join(f"{m} {table[m].mean():.1f}" for m in table))
    for pair in a.pairs.split(","):
        x, y = pair.split("-")
        mean, lo, hi, n = paired(table, x, y)
        print(f"{x} - {y}: {mean:+.1f} [{lo:+.1f}, {hi:+.1f}] over {n} frames")
    return 0


if __name__ == "__main__":
    sys.exit(main())
