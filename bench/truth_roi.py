"""The whole-ROI truth scoring, derived exactly from the two truth strata: pure pandas, no I/O.

Since results schema version 2 the truth is scored in two disjoint strata (:mod:`bench.masks`):
``truth`` (the ROI pixels where the HQ reference has depth) and ``truth_noref`` (the ROI pixels without
one). Their union is every ROI pixel with truth: what the truth columns scored before version 2 and
what a method comparison against the truth over the whole ROI wants. Reference ``truth_roi`` here is that
union, computed from the strata's rows of one (method_key, frame), with ``n`` the scored pixel counts
(``n_valid``; ``n_moving`` for the moving errors) of the strata:

* ``n_reference``, ``n_valid``, ``n_moving``: sums; ``fill_rate = n_valid / n_reference``;
* ``mse_mm2``, ``mae_mm``, ``bias_mm``: ``(n1 * x1 + n2 * x2) / (n1 + n2)`` with ``n = n_valid``
  (a mean over the union of two disjoint pixel sets is the count-weighted mean of the two means);
  ``mse_moving_mm2``, ``mae_moving_mm`` alike with ``n = n_moving`` (both strata use the frame's one
  moving mask); ``rmse_mm = sqrt(mse_mm2)`` of the combined MSE;
* per reference-depth bin (the bins are the truth's depth in both strata): ``n_valid`` summed,
  ``mae_mm`` weighted, ``rmse_mm = sqrt`` of the count-weighted mean of the strata's ``rmse_mm ** 2``.

Not offered, because they do not combine exactly: the plane-fit metrics (each stratum fits its planes
on its own reference pixels, so a neighbourhood that crosses the strata differs in the union) and
``normal_angle_deg`` (central differences across the strata's border). A (method_key, frame) with only
one stratum (the HQ sensor pseudo-method has no ``truth_noref``) gets no ``truth_roi`` rows.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

#: the derived reference's name in a results table
TRUTH_ROI = "truth_roi"
#: the strata it is derived from
STRATA = ("truth", "truth_noref")
#: frame-level metrics it offers -> the count that weights them (None: a count, summed)
FRAME_WEIGHTS = {"n_reference": None, "n_valid": None, "n_moving": None, "mse_mm2": "n_valid",
                 "mae_mm": "n_valid", "bias_mm": "n_valid", "mse_moving_mm2": "n_moving",
                 "mae_moving_mm": "n_moving"}
#: per-bin metrics it offers (n_valid weights mae_mm and the squared rmse_mm)
BIN_METRICS = ("n_valid", "mae_mm", "rmse_mm")
_KEYS = ["schema_version", "method", "method_version", "method_key", "dataset", "dataset_checksum", "sequence",
         "frame"]


def _weighted(x: pd.DataFrame, w: pd.DataFrame) -> pd.Series:
    """Count-weighted mean over the strata (columns); a stratum with no pixel (w = 0, x NaN) adds nothing."""
    num = (x.fillna(0.0) * w.fillna(0.0)).sum(axis=1)
    den = w.fillna(0.0).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return num.where(den > 0) / den.where(den > 0)


def _combine(rows: pd.DataFrame, keys: list[str], metrics: dict[str, str | None],
             derived: dict[str, callable]) -> pd.DataFrame:
    """Rows of ``keys`` x metric with both strata present -> long rows of the union."""
    wide = rows.pivot_table(index=keys, columns=["metric", "reference"], values="value", dropna=False,
                            aggfunc="first")
    both = pd.Series(True, index=wide.index)
    for s in STRATA:   # both strata must have reported the weights
        both &= wide.get(("n_valid", s), pd.Series(np.nan, index=wide.index)).notna()
    wide = wide[both]
    out = {}
    for metric, weight in metrics.items():
        if metric not in wide.columns.get_level_values(0):
            continue
        x = wide[metric].reindex(columns=list(STRATA))
        out[metric] = x.sum(axis=1, min_count=1) if weight is None else \
            _weighted(x, wide[weight].reindex(columns=list(STRATA)))
    for metric, f in derived.items():
        value = f(wide, out)
        if value is not None:
            out[metric] = value
    return pd.DataFrame(out, index=wide.index).reset_index().melt(id_vars=keys, var_name="metric",
                                                                  value_name="value")


def truth_roi_rows(df: pd.DataFrame) -> pd.DataFrame:
    """The ``truth_roi`` rows of a results table ``df`` (:data:`bench.results.COLUMNS`), frame-level and
    per bin, for every (method_key, frame) that has both strata; empty when there is none.

    Example (one frame, 2 shared pixels of error 1 mm, 1 silhouette pixel of error 4 mm):
        >>> base = dict(schema_version=2, method="m", method_version="1", method_key="m@1", dataset="d",
        ...             dataset_checksum="c", sequence="s", frame=0, unit="", bin_lo_m=np.nan, bin_hi_m=np.nan)
        >>> df = pd.DataFrame([dict(base, reference=r, metric=k, value=v) for r, k, v in [
        ...     ("truth", "n_valid", 2), ("truth", "mse_mm2", 1.0), ("truth_noref", "n_valid", 1),
        ...     ("truth_noref", "mse_mm2", 16.0)]])
        >>> t = truth_roi_rows(df).set_index("metric")["value"]
        >>> float(t["mse_mm2"]), float(t["rmse_mm"])
        (6.0, 2.449489742783178)
    """
    from bench.metrics import UNITS

    rows = df[df["reference"].isin(STRATA)]
    if not all((rows["reference"] == s).any() for s in STRATA):
        return df.iloc[0:0].copy()
    keys = [k for k in _KEYS if k in df.columns]
    frame = rows[rows["bin_lo_m"].isna()]
    parts = [_combine(frame, keys, FRAME_WEIGHTS, {
        "rmse_mm": lambda wide, out: np.sqrt(out["mse_mm2"]) if "mse_mm2" in out else None,
        "fill_rate": lambda wide, out: out["n_valid"] / out["n_reference"].where(out["n_reference"] > 0)
        if "n_reference" in out else None})]
    binned = rows[rows["bin_lo_m"].notna() & rows["metric"].isin(BIN_METRICS)].copy()
    if not binned.empty:
        sq = binned[binned["metric"] == "rmse_mm"].assign(metric="_sq", value=lambda d: d["value"] ** 2)
        parts.append(_combine(pd.concat([binned, sq]), keys + ["bin_lo_m", "bin_hi_m"],
                              {"n_valid": None, "mae_mm": "n_valid", "_sq": "n_valid"},
                              {"rmse_mm": lambda wide, out: np.sqrt(out.pop("_sq"))}))
    out = pd.concat([p.dropna(subset=["metric"]) for p in parts], ignore_index=True)
    out = out[out["metric"].isin(set(FRAME_WEIGHTS) | set(BIN_METRICS) | {"rmse_mm", "fill_rate"})]
    out["reference"] = TRUTH_ROI
    out["unit"] = out["metric"].map(UNITS)
    for c in ("bin_lo_m", "bin_hi_m"):
        if c not in out:
            out[c] = np.nan
    return out[list(df.columns)].astype(df.dtypes.to_dict())


def with_truth_roi(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with its :func:`truth_roi_rows` appended (unchanged when it already has some)."""
    if (df["reference"] == TRUTH_ROI).any():
        return df
    extra = truth_roi_rows(df)
    return pd.concat([df, extra], ignore_index=True) if len(extra) else df
