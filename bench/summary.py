"""The leaderboard's numbers: summaries of the results table, pure pandas/numpy, no I/O.

:mod:`bench.report` writes these as Markdown and HTML; everything it shows is computed here from the long
results table (:mod:`bench.results`: one row per dataset, frame, method, reference, metric and optional depth bin).

The columns
    :func:`method_labels` orders the method keys as the seed report's Table I does (:data:`TABLE_I`: Raw, BF,
    JBF, RGF, DDRNet, DDD, SSDD UNet, SSDD LSTM), other methods after them by name, the HQ sensor last; a
    method present in several versions gets one column per version (``" v<version>"`` in its label).

Means over frames with bootstrap intervals
    :func:`frame_values` lays one reference's frame-level rows out as a wide table (one row per frame, one
    column per (metric, method key)); :func:`bootstrap_summary` gives each column's mean over frames (every frame
    of every dataset weighs the same; NaN frames left out, their count in ``n_frames``) and a 95 % percentile
    bootstrap interval: the frames are resampled with replacement, the *same* resamples for every column, so
    the intervals of differences of columns are paired. The interval treats frames as independent; neighbouring
    frames of a sequence are not, so it is narrower than an interval over independent recordings would be.

Depth curves
    :func:`depth_curves` pools the depth-binned rows over frames: MAE weighted by each bin's valid pixels,
    plane-fit RMSE by its fitted points, and the share of points the plane fit excluded; bins holding less than
    :data:`MIN_BIN_SHARE` of a method's pixels are dropped.

The two truth strata
    Against the simulator's truth the ROI's pixels are split by the HQ reference
    (:func:`bench.masks.truth_strata`): ``truth`` scores the pixels the HQ reference scores (like with like),
    :data:`NOREF` the ROI pixels without a reference (silhouettes, holes, the edge rule's mask).
    :func:`noref_share` is each frame's share of the second stratum.

Does the reference rank the methods as the truth does?
    :func:`ranking_check` orders the methods by their mean against the HQ reference and against the truth on
    the same pixels (MSE and RMSE, :data:`RANKING_METRICS`) and gives every pair's per-frame difference with a
    paired bootstrap interval in each scoring; a pair is decided *wrongly* by the reference when the two
    differences have opposite signs and both intervals are clear of zero (:func:`decided_wrongly`). It checks
    all the reference's pixels or those away from its depth edges (:data:`RANKING_STRATA`); the second is the
    order the leaderboard gives as its ranking (at the reference's depth edges its error and a CNN's are
    correlated: :mod:`bench.masks`).
"""
from __future__ import annotations

import re
import warnings

import numpy as np
import pandas as pd

from bench.metrics import BINNED

#: Table I of the seed report: column order and labels; names are matched after lower-casing and
#: removing non-alphanumerics, with the aliases of the registered implementations.
TABLE_I = (
    ("raw", "Raw", ("raw",)),
    ("bf", "BF", ("bf", "bilateral", "bilateralfilter")),
    ("jbf", "JBF", ("jbf", "jointbilateral", "jointbilateralfilter")),
    ("rgf", "RGF", ("rgf", "rollingguidance", "rollingguidancefilter")),
    ("ddrnet", "DDRNet", ("ddrnet",)),
    ("ddd", "DDD", ("ddd", "deepdepthdenoising")),
    ("ssdd_unet", "SSDD UNet", ("ssddunet", "ssdd")),
    ("ssdd_lstm", "SSDD LSTM", ("ssddlstm", "ssddlstmunet")),
)
#: Depth bins holding less than this share of a method's scored pixels are left out of the depth curves.
MIN_BIN_SHARE = 0.001
HQ_SENSOR = "hq_sensor"
#: the truth stratum of the ROI pixels without an HQ reference (:func:`bench.masks.truth_strata`)
NOREF = "truth_noref"
#: the metrics the ranking check compares the two scorings on (key -> short name)
RANKING_METRICS = {"mse_mm2": "MSE", "rmse_mm": "RMSE"}
#: the strata of :func:`ranking_check`: name -> (reference, truth) names of the results table
RANKING_STRATA = {"all": ("hq", "truth"), "interior": ("hq_interior", "truth_interior")}


# ----------------------------------------------------------------------------------- columns
def _norm(name: str) -> str:
    return re.sub(r"[^a-z0-9]", "", name.lower())


def table_i_slot(name: str) -> int | None:
    """Position of a method name in Table I's column order, or None.

    >>> table_i_slot("rolling_guidance"), table_i_slot("SSDD"), table_i_slot("gaussian")
    (3, 6, None)
    """
    n = _norm(name)
    for k, (_, _, aliases) in enumerate(TABLE_I):
        if n in aliases:
            return k
    return None


def method_labels(df: pd.DataFrame, *, include_hq_sensor: bool = False) -> dict[str, str]:
    """Method key -> column label, in Table I order, other methods after them by name, HQ sensor last.

    >>> df = pd.DataFrame({"method": ["gaussian", "raw", "bilateral", "bilateral"],
    ...                    "method_key": ["g@1", "r@1", "b@1", "b@2"], "method_version": ["1", "1", "1", "2"]})
    >>> method_labels(df)
    {'r@1': 'Raw', 'b@1': 'BF v1', 'b@2': 'BF v2', 'g@1': 'gaussian'}
    """
    keys = df[["method", "method_key", "method_version"]].drop_duplicates()
    if not include_hq_sensor:
        keys = keys[keys["method"] != HQ_SENSOR]
    counts = keys["method"].value_counts()

    def sort_key(r):
        slot = table_i_slot(r.method)
        return (2 if r.method == HQ_SENSOR else 0 if slot is not None else 1, slot or 0, r.method, r.method_key)

    out = {}
    for r in sorted(keys.itertuples(), key=sort_key):
        slot = table_i_slot(r.method)
        label = "HQ sensor" if r.method == HQ_SENSOR else TABLE_I[slot][1] if slot is not None else r.method
        if counts[r.method] > 1:
            label += f" v{r.method_version}"
        out[r.method_key] = label
    return out


# ----------------------------------------------------------------------------------- means over frames
def frame_values(df: pd.DataFrame, reference: str) -> pd.DataFrame:
    """Frame-level rows of one reference as a wide table: index (dataset_checksum, frame), columns (metric, method_key).

    Depth-binned rows are left out; a duplicated row keeps its first value.

    >>> df = pd.DataFrame({"reference": "hq", "bin_lo_m": np.nan, "dataset_checksum": "c", "frame": [0, 0, 1],
    ...                    "metric": "mae_mm", "method_key": ["a", "b", "a"], "value": [1.0, 2.0, 3.0]})
    >>> w = frame_values(df, "hq")
    >>> w.index.tolist(), w.columns.tolist()
    ([('c', 0), ('c', 1)], [('mae_mm', 'a'), ('mae_mm', 'b')])
    >>> w.to_numpy()
    array([[ 1.,  2.],
           [ 3., nan]])
    """
    rows = df[(df["reference"] == reference) & df["bin_lo_m"].isna()]
    v = rows.set_index(["dataset_checksum", "frame", "metric", "method_key"])["value"]
    wide = v[~v.index.duplicated()].unstack(["metric", "method_key"])
    return wide.sort_index().sort_index(axis=1)


def bootstrap_summary(wide: pd.DataFrame, *, n_boot: int = 2000, seed: int = 0, level: float = 0.95) -> pd.DataFrame:
    """Mean over frames and a percentile bootstrap interval for every column of ``wide``.

    Frames (rows) are resampled with replacement ``n_boot`` times with ``numpy.random.default_rng(seed)``;
    the same resamples serve every column (a paired bootstrap). NaN values are left out of the
    means. Returns a frame indexed like ``wide.columns`` with ``mean, lo, hi, n_frames``.

    >>> bootstrap_summary(pd.DataFrame({"const": [3.0, 3.0, 3.0], "gap": [1.0, np.nan, 3.0]}), n_boot=200)
           mean   lo   hi  n_frames
    const   3.0  3.0  3.0         3
    gap     2.0  1.0  3.0         2
    """
    F = wide.to_numpy(dtype=np.float64)
    n = F.shape[0]
    valid = np.isfinite(F)
    Z = np.where(valid, F, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = Z.sum(axis=0) / valid.sum(axis=0)
    if n == 0:
        lo = hi = mean
    else:
        counts = np.random.default_rng(seed).multinomial(n, np.full(n, 1.0 / n), size=n_boot).astype(np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            boot = (counts @ Z) / (counts @ valid)
        a = (1.0 - level) / 2.0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)    # all-NaN columns give NaN intervals
            lo = np.nanquantile(boot, a, axis=0)
            hi = np.nanquantile(boot, 1.0 - a, axis=0)
    return pd.DataFrame({"mean": mean, "lo": lo, "hi": hi, "n_frames": valid.sum(axis=0)}, index=wide.columns)


# ----------------------------------------------------------------------------------- depth curves
def depth_curves(df: pd.DataFrame, reference: str) -> pd.DataFrame:
    """Binned rows pooled over frames: per (method key, depth bin) MAE, plane-fit RMSE, excluded share."""
    b = df[(df["reference"] == reference) & df["bin_lo_m"].notna()]
    if b.empty:
        return pd.DataFrame(columns=["method_key", "depth_m", "mae_mm", "plane_fit_rmse_mm", "excluded_share", "n_valid"])
    w = b.set_index(["method_key", "dataset_checksum", "frame", "bin_lo_m", "bin_hi_m", "metric"])["value"]
    w = w[~w.index.duplicated()].unstack("metric").reindex(columns=list(BINNED)).reset_index()
    w["abs_sum"] = np.nan_to_num(w["mae_mm"]) * w["n_valid"]
    w["pf_sq"] = np.nan_to_num(w["plane_fit_rmse_mm"]) ** 2 * w["plane_fit_n"]
    g = w.groupby(["method_key", "bin_lo_m", "bin_hi_m"], as_index=False)[
        ["n_valid", "abs_sum", "plane_fit_n", "pf_sq", "plane_fit_excluded"]].sum()
    with np.errstate(invalid="ignore", divide="ignore"):
        g["mae_mm"] = np.where(g["n_valid"] > 0, g["abs_sum"] / g["n_valid"], np.nan)
        g["plane_fit_rmse_mm"] = np.where(g["plane_fit_n"] > 0, np.sqrt(g["pf_sq"] / g["plane_fit_n"]), np.nan)
        tot = g["plane_fit_n"] + g["plane_fit_excluded"]
        g["excluded_share"] = np.where(tot > 0, g["plane_fit_excluded"] / tot, np.nan)
    g["depth_m"] = (g["bin_lo_m"] + g["bin_hi_m"]) / 2
    g = g[g["n_valid"] >= MIN_BIN_SHARE * g.groupby("method_key")["n_valid"].transform("sum")]
    return g[["method_key", "depth_m", "mae_mm", "plane_fit_rmse_mm", "excluded_share", "n_valid"]]


# ----------------------------------------------------------------------------------- truth strata and ranking
def noref_share(df: pd.DataFrame) -> pd.Series:
    """Per frame (index ``(dataset_checksum, frame)``): the share of the ROI's truth pixels that have no HQ
    reference, ``n_reference(truth_noref) / (n_reference(truth) + n_reference(truth_noref))`` (``n_reference`` is
    the same for every method; the first method key's rows are read, not the HQ sensor's).

    >>> df = pd.DataFrame({"reference": ["truth", NOREF], "bin_lo_m": np.nan, "metric": "n_reference",
    ...                    "method": "raw", "method_key": "raw@1", "dataset_checksum": "c", "frame": 0,
    ...                    "value": [75.0, 25.0]})
    >>> noref_share(df).tolist()
    [0.25]
    """
    w = _reference_counts(df, ("truth", NOREF))
    if w is None:
        return pd.Series(dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (w[NOREF] / (w["truth"] + w[NOREF])).sort_index()


def edge_share(df: pd.DataFrame) -> pd.Series:
    """Per frame (index ``(dataset_checksum, frame)``): the share of the HQ reference's pixels that lie at its
    depth edges, ``1 - n_reference(hq_interior) / n_reference(hq)`` (:func:`bench.masks.interior_strata`; the first
    method key's rows).

    >>> df = pd.DataFrame({"reference": ["hq", "hq_interior"], "bin_lo_m": np.nan, "metric": "n_reference",
    ...                    "method": "raw", "method_key": "raw@1", "dataset_checksum": "c", "frame": 0,
    ...                    "value": [80.0, 60.0]})
    >>> edge_share(df).tolist()
    [0.25]
    """
    w = _reference_counts(df, ("hq", "hq_interior"))
    if w is None:
        return pd.Series(dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (1 - w["hq_interior"] / w["hq"]).sort_index()


def _reference_counts(df: pd.DataFrame, references: tuple[str, ...]) -> pd.DataFrame | None:
    """Per frame (index ``(dataset_checksum, frame)``), one column per name of ``references``: the frame's
    ``n_reference`` there (the same for every method: the first method key's rows, not the HQ sensor's); ``None``
    without such rows."""
    rows = df[df["reference"].isin(references) & df["bin_lo_m"].isna() & (df["metric"] == "n_reference")
              & (df["method"] != HQ_SENSOR)]
    if rows.empty:
        return None
    first = sorted(rows["method_key"].unique())[0]
    v = rows[rows["method_key"] == first].set_index(["dataset_checksum", "frame", "reference"])["value"]
    return v[~v.index.duplicated()].unstack("reference").reindex(columns=list(references))


def ranking_check(df: pd.DataFrame, *, stratum: str = "all", n_boot: int = 2000, seed: int = 0) -> dict:
    """Does the HQ reference rank the methods as the truth does on the same pixels?

    On the frames with truth, per metric of :data:`RANKING_METRICS`: the methods (not the HQ sensor) ordered by
    their mean over frames against the HQ reference (scoring ``"hq"``) and against the truth on the same pixels
    (``"truth"``), whether the two orders are equal, and for every pair ``(a, b)`` the per-frame difference
    ``a - b`` (mean and 95 % paired bootstrap interval over frames) in each scoring, and with ``stratum`` ``"all"``
    against the truth on the pixels without a reference (``"truth_noref"``). ``"wrong"`` lists the pairs the
    reference decides against the truth: opposite signs, both intervals clear of zero.

    ``stratum`` (:data:`RANKING_STRATA`): ``"all"`` scores all the reference's pixels (references ``"hq"`` and
    ``"truth"`` of the table), ``"interior"`` those away from its depth edges (``"hq_interior"``,
    ``"truth_interior"``; :func:`bench.masks.interior_strata`). Returns ``{metric: {"order": {scoring:
    [key, ...]}, "same": bool, "pairs": [(a, b, {scoring: (mean, lo, hi)})], "wrong": [(a, b)]}}``; empty
    without truth rows of that stratum."""
    if stratum not in RANKING_STRATA:
        raise ValueError(f"ranking stratum must be one of {', '.join(RANKING_STRATA)}, got {stratum!r}")
    hq_ref, truth_ref = RANKING_STRATA[stratum]
    keys = [k for k in method_labels(df[df["reference"] == truth_ref])
            if k in set(df.loc[df["reference"] == hq_ref, "method_key"])]
    if len(keys) < 2:
        return {}
    wides = {"hq": frame_values(df, hq_ref), "truth": frame_values(df, truth_ref)}
    if stratum == "all":
        wides[NOREF] = frame_values(df, NOREF)
    frames = wides["truth"].index
    out = {}
    for metric in RANKING_METRICS:
        cols = {ref: w.reindex(index=frames, columns=[(metric, k) for k in keys]) for ref, w in wides.items()}
        order = {ref: [k for _, k in sorted(zip(cols[ref].mean().to_numpy(), keys), key=lambda t: (np.nan_to_num(t[0], nan=np.inf), t[1]))]
                 for ref in ("hq", "truth")}
        diffs = {}
        for ref, c in cols.items():
            d = pd.DataFrame({(a, b): c[(metric, a)].to_numpy() - c[(metric, b)].to_numpy()
                              for i, a in enumerate(keys) for b in keys[i + 1:]}, index=frames)
            diffs[ref] = bootstrap_summary(d, n_boot=n_boot, seed=seed)
        pairs = [(a, b, {ref: tuple(float(diffs[ref].loc[(a, b), c]) for c in ("mean", "lo", "hi")) for ref in diffs})
                 for i, a in enumerate(keys) for b in keys[i + 1:]]
        out[metric] = {"order": order, "same": order["hq"] == order["truth"], "pairs": pairs,
                       "wrong": [(a, b) for a, b, d in pairs if decided_wrongly(d["hq"], d["truth"])]}
    return out


def decided_wrongly(hq: tuple, truth: tuple) -> bool:
    """A pair the HQ reference and the truth order oppositely, each with its 95 % interval clear of zero; where
    either interval straddles zero the flip is within that scoring's noise, not a contradiction.

    Each argument is ``(mean, lo, hi)`` of the difference ``a - b``:

    >>> decided_wrongly((-1.0, -1.5, -0.5), (2.0, 1.0, 3.0))
    True
    >>> decided_wrongly((-1.0, -1.5, +0.5), (2.0, 1.0, 3.0)), decided_wrongly((-1.0, -1.5, -0.5), (-2.0, -3.0, -1.0))
    (False, False)
    """
    if not (np.isfinite(hq[0]) and np.isfinite(truth[0])) or np.sign(hq[0]) == np.sign(truth[0]):
        return False
    return all(t[1] > 0 or t[2] < 0 for t in (hq, truth))
