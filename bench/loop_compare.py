"""How the leaderboard changes when the alignment loop models the effects (issue 12, item 4).

Pure pandas, no I/O: two results tables of the same methods on the same session, aligned without
the loop (``before``) and with it (``after``), become one table per (reference, metric): each
method's mean over frames before and after, its rank before and after (1 = lowest error), and
the change. ``rank_agreement`` says whether the ranking against the HQ reference matches the
ranking against the truth (simulated data), before and after.

Example:
    >>> import pandas as pd
    >>> def t(v): return pd.DataFrame({"method": ["raw", "bf"], "reference": "hq", "metric": "mae_mm",
    ...                                "bin_lo_m": float("nan"), "frame": 0, "value": v})
    >>> compare_leaderboards(t([10.0, 8.0]), t([6.0, 7.0]))[["method", "rank_before", "rank_after"]].values.tolist()
    [['bf', 1, 2], ['raw', 2, 1]]
"""
from __future__ import annotations

import numpy as np
import pandas as pd

METRICS = ("mae_mm", "rmse_mm", "mse_mm2")


def _means(df: pd.DataFrame, metrics) -> pd.DataFrame:
    whole = df[df["bin_lo_m"].isna() & df["metric"].isin(metrics)]
    return whole.groupby(["reference", "metric", "method"], as_index=False)["value"].mean()


def compare_leaderboards(before: pd.DataFrame, after: pd.DataFrame, *, metrics=METRICS) -> pd.DataFrame:
    """Columns: reference, metric, method, before, after, change, rank_before, rank_after (see the module docstring)."""
    b = _means(before, metrics).rename(columns={"value": "before"})
    a = _means(after, metrics).rename(columns={"value": "after"})
    m = b.merge(a, on=["reference", "metric", "method"], how="outer")
    m["change"] = m["after"] - m["before"]
    for col in ("before", "after"):
        m[f"rank_{col}"] = m.groupby(["reference", "metric"])[col].rank(method="min").astype("Int64")
    return m.sort_values(["reference", "metric", "rank_before", "method"]).reset_index(drop=True)


def rank_agreement(table: pd.DataFrame, *, metric: str = "rmse_mm", exclude=("hq_sensor",)) -> dict:
    """Whether the ranking against the HQ reference equals the one against truth, before and after."""
    out = {}
    for col in ("before", "after"):
        ranks = {}
        for ref in ("hq", "truth"):
            sub = table[(table["reference"] == ref) & (table["metric"] == metric) & ~table["method"].isin(exclude)]
            ranks[ref] = list(sub.sort_values(col)["method"])
        out[col] = bool(ranks["hq"] and ranks["hq"] == ranks["truth"])
        out[f"{col}_order"] = ranks
    return out


def markdown(table: pd.DataFrame, *, labels: tuple[str, str] = ("without the loop", "with it")) -> str:
    """The comparison as a Markdown table; ``labels``: the column heads of "before" and "after"."""
    lines = [f"| reference | metric | method | {labels[0]} | {labels[1]} | change | rank | |",
             "|---|---|---|--:|--:|--:|--:|--:|"]
    for r in table.itertuples():
        ch = "" if not np.isfinite(r.change) else f"{r.change:+.2f}"
        lines.append(f"| {r.reference} | {r.metric} | {r.method} | {r.before:.2f} | {r.after:.2f} | {ch} | "
                     f"{r.rank_before} | -> {r.rank_after} |")
    return "\n".join(lines)
