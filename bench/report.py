"""The leaderboard: Markdown and a self-contained HTML page, rebuilt from the results table alone.

:func:`write_report` reads ``RESULTS/results.parquet`` (and, for the qualitative figure only, the
small previews in ``RESULTS/previews/``) and writes ``leaderboard.md``, ``leaderboard.html`` (images
inlined as base64, no external resources) and ``figures/*.png`` into the results folder. The report
is derived data: it is replaced on every run or ``depthbench bench report``.

Every number shown is computed by :mod:`bench.summary` (pure pandas/numpy); this module lays them out.
Summary numbers are means over frames of the per-frame metric (every frame of every dataset
weighs the same) with 95 % percentile bootstrap intervals: frames are resampled with replacement
(2000 resamples, seed 0), the same resamples for every method and metric (paired).

Against the simulator's truth the pixels are split by the HQ reference (:func:`bench.masks.truth_strata`):
the truth summary scores the same pixels as the HQ summary (like with like), and the ROI pixels without
a reference ("silhouettes / no reference") are their own stratum, scored against the truth only, with
their share of the ROI. The section "Away from the reference's depth edges" scores the reference's pixels more than
1 px from its own depth edges (:func:`bench.masks.interior_strata`), against it and against the truth: the rows the
methods are ranked by. :func:`bench.summary.ranking_check` says whether the HQ reference orders the methods as the
truth does on the same pixels (MSE and RMSE), there and on all its pixels, with paired intervals of every pair's
difference.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from bench import plots
from bench import results as R
from bench.masks import EDGE_FILL_PX, EDGE_REL, EDGE_WIDTH_PX
from bench.summary import (MIN_BIN_SHARE, NOREF, RANKING_METRICS, RANKING_STRATA, TABLE_I, bootstrap_summary,
                           depth_curves, edge_share, frame_values, method_labels, noref_share, ranking_check,
                           table_i_slot)
from depthbench.fsutil import atomic_write_text, staged_directory
from depthbench.markdown_html import html_page, markdown_to_html

#: The published numbers of the seed report's Table I (other data, other sensors; not comparable).
PUBLISHED = (
    {"label": "DDD [4] (Sterzentsenko et al.): RMSE (mm) of the plane fit, their 70-pair evaluation set",
     "metric": "plane_fit_rmse_mm",
     "values": {"bf": 73.25, "rgf": 81.35, "ddrnet": 239.06, "ddd": 58.95}},
    {"label": "SSDD [5] (Shabanov et al.): \"MSE (mm)\" as printed, their test sequences",
     "metric": "mse_mm2",
     "values": {"raw": 57.22, "bf": 56.39, "rgf": 49.49, "ddrnet": 57.08, "ddd": 84.07, "ssdd_unet": 31.61,
                "ssdd_lstm": 21.02}},
)
PUBLISHED_NOTE = ("Published numbers of the seed report's Table I, on other data with other sensors and other "
                  "error definitions: shown for orientation only, not comparable with the rows above. DDD gives no "
                  "raw-input error; SSDD prints its error as \"MSE (mm)\", a unit that fits neither MSE (mm²) nor "
                  "RMSE exactly.")

SUMMARY_METRICS = {
    "mse_mm2": "MSE (mm²)", "rmse_mm": "RMSE (mm)", "mae_mm": "MAE (mm)",
    "plane_fit_rmse_mm": "plane-fit RMSE (mm)", "fill_rate": "fill rate (%)", "normal_angle_deg": "normal angle (°)",
    "mse_moving_mm2": "MSE, moving pixels (mm²)", "mae_moving_mm": "MAE, moving pixels (mm)",
}
SEQUENCE_METRICS = ("rmse_mm", "mae_mm", "plane_fit_rmse_mm", "fill_rate")


@dataclass
class ReportPaths:
    """Files written by :func:`write_report`."""

    markdown: Path
    html: Path
    figures: list[Path] = field(default_factory=list)

    def moved(self, src: Path, dst: Path) -> "ReportPaths":
        """The same files after the folder ``src`` was renamed ``dst``."""
        def mv(p: Path) -> Path:
            return Path(dst) / Path(p).relative_to(src)
        return ReportPaths(mv(self.markdown), mv(self.html), [mv(p) for p in self.figures])


# ----------------------------------------------------------------------------------- formatting
def _fmt(x: float, digits: int = 2) -> str:
    if x is None or not np.isfinite(x):
        return "–"
    return f"{x:.{digits}f}"


def _cell(s: pd.DataFrame, metric: str, key: str, *, n_total: int) -> str:
    """``mean [lo, hi]``, with ``(n=k)`` when the value exists on fewer than all frames."""
    if (metric, key) not in s.index:
        return "–"
    r = s.loc[(metric, key)]
    scale = 100.0 if metric == "fill_rate" else 1.0
    m, lo, hi = r["mean"] * scale, r["lo"] * scale, r["hi"] * scale
    if not np.isfinite(m):
        return "–"
    n = int(r["n_frames"])
    return f"{_fmt(m)} [{_fmt(lo)}, {_fmt(hi)}]" + (f" (n={n})" if n < n_total else "")


class _Doc:
    """The report as Markdown blocks; each keeps the CSS class its HTML rendering gets."""

    def __init__(self) -> None:
        self.blocks: list[tuple[str, str | None, list[str] | None]] = []    # (markdown, class, table row classes)
        self.figures: dict[str, bytes] = {}                                 # file name in figures/ -> PNG

    def heading(self, text: str, level: int = 2) -> None:
        self.blocks.append((f"{'#' * level} {text}\n", None, None))

    def para(self, text: str, *, cls: str | None = None) -> None:
        self.blocks.append((text + "\n", cls, None))

    def table(self, header: list[str], rows: list[list[str]], *, row_classes: list[str] | None = None) -> None:
        lines = ["| " + " | ".join(header) + " |", "|" + "|".join([":--"] + ["--:"] * (len(header) - 1)) + "|"]
        lines += ["| " + " | ".join(x.replace("|", "\\|") for x in r) + " |" for r in rows]
        self.blocks.append(("\n".join(lines) + "\n", None, row_classes))

    def figure(self, name: str, png: bytes, alt: str) -> None:
        self.figures[name] = png
        self.blocks.append((f"![{alt}](figures/{name})\n", None, None))

    def markdown(self) -> str:
        return "\n".join(md for md, _, _ in self.blocks)

    def html(self) -> str:
        images = {f"figures/{name}": png for name, png in self.figures.items()}
        body = "".join(markdown_to_html(md, cls=cls, row_classes=rows, images=images) for md, cls, rows in self.blocks)
        return html_page(body, title="depthbench leaderboard", css=_CSS)


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:2em auto;max-width:1250px;color:#222;padding:0 1em}
h1{font-size:1.6em}h2{margin-top:1.8em;border-bottom:1px solid #ddd;padding-bottom:.2em}
table{border-collapse:collapse;margin:.6em 0 1.2em;font-size:.88em}
th,td{border:1px solid #ccc;padding:.3em .55em;text-align:right;white-space:nowrap}
th:first-child,td:first-child{text-align:left;white-space:normal;max-width:26em}
thead th{background:#f0f3f7}
tr.published td{background:#fbf7ea;color:#6b5d35;font-style:italic}
tr.separator td{background:#f6f6f6;color:#555;font-weight:600;text-align:left}
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #eee}
figcaption{font-size:.85em;color:#555}
p.note{font-size:.9em;color:#444;background:#f7f7f7;padding:.5em .8em;border-left:3px solid #bbb}
code{background:#f3f3f3;padding:0 .2em}
"""


# ----------------------------------------------------------------------------------- report
def _summary_section(doc: _Doc, df: pd.DataFrame, reference: str, *, n_boot: int, seed: int) -> None:
    truth = reference == "truth"
    labels = method_labels(df[df["reference"] == reference], include_hq_sensor=truth)
    if not labels:
        return
    wide = frame_values(df, reference)
    s = bootstrap_summary(wide, n_boot=n_boot, seed=seed)
    n_frames = len(wide)
    doc.heading("Summary against the simulator's truth, on the HQ reference's pixels" if truth
                else "Summary against the HQ reference")
    header = ["metric"] + list(labels.values())
    rows = [[name] + [_cell(s, metric, k, n_total=n_frames) for k in labels] for metric, name in SUMMARY_METRICS.items()]
    classes = [""] * len(rows)
    if not truth:
        rows.append(["Published (seed report Table I), other data: not comparable"] + [""] * len(labels))
        classes.append("separator")
        published = _published_rows(df, labels)
        rows += published
        classes += ["published"] * len(published)
    doc.table(header, rows, row_classes=classes)
    doc.para(f"Mean over {n_frames} frames of the per-frame value, with its 95 % bootstrap interval "
             f"({n_boot} resamples of the frames, seed {seed}, the same resamples for every column). "
             "Errors are over pixels valid in both the method's output and the reference, inside the ROI; "
             "the fill rate is the share of reference pixels the method leaves valid. (n=k): the value exists on k "
             "frames only (a method that needs colour on frames without it, or frames where nothing is scored). "
             "Moving pixels: those whose depth changed by more than the moving threshold since the previous frame, "
             "in the truth where the dataset has one, else in the HQ reference (`bench.metrics.moving_mask`; "
             "the first frame has none).",
             cls="note")
    if truth:
        doc.para("Like with like: these columns score the truth on exactly the pixels the HQ summary scores (ROI "
                 "pixels where the HQ reference has depth). The ROI pixels without a reference are scored separately "
                 "below (\"Silhouettes / no reference\"). The **HQ sensor** column scores the warped HQ depth itself "
                 "against the truth: the part of every method's error against the HQ reference that is the "
                 "reference's own error.", cls="note")
    else:
        doc.para(PUBLISHED_NOTE, cls="note")
    png = plots.summary_bars(s, labels, metrics={"rmse_mm": "RMSE (mm)", "mae_mm": "MAE (mm)",
                                                 "plane_fit_rmse_mm": "plane-fit RMSE (mm)"},
                             title=f"against the {'truth' if truth else 'HQ reference'} (95 % bootstrap intervals)")
    doc.figure(f"summary_{reference}.png", png, f"Summary against the {'truth' if truth else 'HQ reference'}")


def _noref_section(doc: _Doc, df: pd.DataFrame, *, n_boot: int, seed: int) -> None:
    """The ROI pixels without an HQ reference, scored against the truth only."""
    part = df[df["reference"] == NOREF]
    labels = method_labels(part)
    if not labels:
        return
    wide = frame_values(df, NOREF)
    s = bootstrap_summary(wide, n_boot=n_boot, seed=seed)
    share = noref_share(df)
    sh = bootstrap_summary(share.to_frame("share"), n_boot=n_boot, seed=seed).loc["share"]
    doc.heading("Silhouettes / no reference: ROI pixels without an HQ reference, against the truth only")
    metrics = {k: v for k, v in SUMMARY_METRICS.items() if k in ("mse_mm2", "rmse_mm", "mae_mm", "fill_rate")}
    rows = [[name] + [_cell(s, metric, k, n_total=len(wide)) for k in labels] for metric, name in metrics.items()]
    doc.table(["metric"] + list(labels.values()), rows)
    doc.para(f"**The HQ reference scores none of these pixels**: they are the ROI pixels where it has no depth "
             f"(HQ sensor holes and mixed pixels along silhouettes, the gap past a surface's last HQ sample, "
             f"occlusion shadows, the edge rule's mask), {100 * sh['mean']:.1f} % [{100 * sh['lo']:.1f}, "
             f"{100 * sh['hi']:.1f}] of the ROI's truth pixels (mean over {len(share)} frames, 95 % bootstrap). Only "
             "the simulator's truth scores them, here; neither summary above includes them. Their errors are those "
             "of depth edges, where the methods differ most.", cls="note")


INTERIOR_NOTE = (
    "At a silhouette the reference's last foreground pixels read a mix of the two surfaces (a time-of-flight pixel "
    "integrates its footprint; the warp interpolates), and so do the outputs of methods that regress across the edge "
    "(a CNN's): there the reference's error and theirs are correlated, and the reference favours them. Away from its "
    "depth edges it does not. Which pixels those are is decided by the reference alone (`bench.masks.depth_edge_mask`: "
    f"within {EDGE_WIDTH_PX:g} px of a jump of over {100 * EDGE_REL:g} % in its 3 x 3 neighbourhood, its holes up to "
    f"{EDGE_FILL_PX} px filled from their farthest neighbour), so real captures have them too.")


def _interior_section(doc: _Doc, df: pd.DataFrame, *, n_boot: int, seed: int) -> None:
    """The summary away from the reference's depth edges: the pixels whose order the leaderboard ranks by."""
    refs = [r for r in RANKING_STRATA["interior"] if (df["reference"] == r).any()]
    if not refs:
        return
    share = edge_share(df)
    sh = bootstrap_summary(share.to_frame("share"), n_boot=n_boot, seed=seed).loc["share"]
    labels = method_labels(df[df["reference"].isin(refs)], include_hq_sensor=True)
    doc.heading("Away from the reference's depth edges (the ranking)")
    metrics = {k: v for k, v in SUMMARY_METRICS.items() if k in ("mse_mm2", "rmse_mm", "mae_mm", "plane_fit_rmse_mm")}
    rows, summaries = [], {}
    for ref in refs:
        s = summaries[ref] = bootstrap_summary(frame_values(df, ref), n_boot=n_boot, seed=seed)
        against = "HQ reference" if ref == "hq_interior" else "truth"
        rows += [[f"{name}, against the {against}"] + [_cell(s, m, k, n_total=len(share)) for k in labels]
                 for m, name in metrics.items()]
    doc.table(["metric"] + list(labels.values()), rows)
    order = _interior_order(summaries.get("hq_interior"), labels)
    if order:
        doc.para(f"**Ranking** (MSE against the HQ reference, away from its depth edges; best first): {order}.")
    doc.para(f"The reference's pixels more than {EDGE_WIDTH_PX:g} px from its own depth edges: {100 * (1 - sh['mean']):.1f} % "
             f"[{100 * (1 - sh['hi']):.1f}, {100 * (1 - sh['lo']):.1f}] of them (mean over {len(share)} frames, 95 % "
             "bootstrap). The methods are ranked by these rows; the summaries above score all the reference's "
             "pixels. " + INTERIOR_NOTE, cls="note")


def _interior_order(summary: pd.DataFrame | None, labels: dict) -> str:
    """The methods ordered by their mean MSE over frames in ``summary`` (:func:`bootstrap_summary` against
    ``hq_interior``, which does not score the HQ sensor)."""
    if summary is None:
        return ""
    means = {k: summary.loc[("mse_mm2", k), "mean"] for k in labels if ("mse_mm2", k) in summary.index}
    return " < ".join(labels[k] for k in sorted(means, key=lambda k: (np.nan_to_num(means[k], nan=np.inf), k)))


def _ranking_verdicts(check: dict, labels: dict, where: str) -> str:
    lines = []
    for metric, c in check.items():
        o = {ref: " < ".join(labels[k] for k in c["order"][ref]) for ref in ("hq", "truth")}
        flips = sum(np.sign(d["hq"][0]) != np.sign(d["truth"][0]) for _, _, d in c["pairs"])
        verdict = ("**yes**, the same order" if c["same"] else
                   f"**no**, the orders differ in {flips} of {len(c['pairs'])} pairs; in {len(c['wrong'])} of them "
                   "both scorings' 95 % intervals are clear of zero (the reference contradicts the truth), in the "
                   "others the flip is within one scoring's noise")
        lines.append(f"{RANKING_METRICS[metric]}: {verdict} (against the HQ reference: {o['hq']}; against the truth on "
                     f"the same pixels: {o['truth']}).")
    return f"**{where}**: " + " ".join(lines)


def _ranking_section(doc: _Doc, df: pd.DataFrame, *, n_boot: int, seed: int) -> None:
    checks = {st: ranking_check(df, stratum=st, n_boot=n_boot, seed=seed) for st in ("interior", "all")}
    checks = {st: c for st, c in checks.items() if c}
    if not checks:
        return
    labels = method_labels(df)
    doc.heading("Does the HQ reference rank the methods as the truth does?")
    where = {"interior": "Away from the reference's depth edges (the leaderboard's ranking)",
             "all": "On all the reference's pixels"}
    for st, c in checks.items():
        doc.para(_ranking_verdicts(c, labels, where[st]))

    def cell(t):
        return "–" if t is None or not np.isfinite(t[0]) else f"{t[0]:+.2f} [{t[1]:+.2f}, {t[2]:+.2f}]"

    def agree(d):
        return "yes" if np.sign(d["hq"][0]) == np.sign(d["truth"][0]) else "**no**"

    header, first = ["pair, metric (difference a − b; < 0: a better)"], next(iter(checks.values()))
    short = {"interior": "away from edges", "all": "all pixels"}
    for st in checks:
        header += [f"{short[st]}: against the HQ reference", f"{short[st]}: against the truth", "same sign"]
    header.append("against the truth, silhouettes / no reference")
    rows = []
    for metric in first:
        by_pair = {st: {(a, b): d for a, b, d in c[metric]["pairs"]} for st, c in checks.items()}
        for a, b, _ in first[metric]["pairs"]:
            row = [f"{labels[a]} − {labels[b]}, {RANKING_METRICS[metric]}"]
            for st in checks:
                d = by_pair[st].get((a, b))
                row += ["–", "–", ""] if d is None else [cell(d["hq"]), cell(d["truth"]), agree(d)]
            row.append(cell(by_pair.get("all", {}).get((a, b), {}).get(NOREF)))
            rows.append(row)
    doc.table(header, rows)
    doc.para(f"Mean over the frames with truth of the per-frame difference, with its 95 % paired bootstrap interval "
             f"({n_boot} resamples of the frames, seed {seed}). Within each stratum the reference and the truth score "
             "the same pixels; the last column scores the ROI pixels the reference leaves out, where only the truth "
             "can say which method is better. " + INTERIOR_NOTE, cls="note")


def _sequence_section(doc: _Doc, df: pd.DataFrame) -> None:
    hq = df[(df["reference"] == "hq") & df["bin_lo_m"].isna() & df["metric"].isin(SEQUENCE_METRICS)]
    labels = method_labels(hq)
    doc.heading("Per sequence (against the HQ reference)")
    for seq, part in hq.groupby("sequence", sort=True):
        names = sorted(part["dataset"].unique())
        n = part[["dataset_checksum", "frame"]].drop_duplicates().shape[0]
        doc.heading(f"{seq} ({', '.join(names)}; {n} frames)", level=3)
        means = part.groupby(["metric", "method_key"])["value"].mean()
        rows = []
        for metric in SEQUENCE_METRICS:
            scale = 100.0 if metric == "fill_rate" else 1.0
            rows.append([SUMMARY_METRICS[metric]] + [_fmt(means.get((metric, k), np.nan) * scale) for k in labels])
        doc.table(["metric"] + list(labels.values()), rows)


def _coverage_section(doc: _Doc, df: pd.DataFrame, config: dict | None) -> None:
    f = df[df["bin_lo_m"].isna() & df["metric"].isin(["plane_fit_n", "plane_fit_excluded_few",
                                                       "plane_fit_excluded_degenerate", "plane_fit_neighbors_median",
                                                       "n_reference"])]
    labels = method_labels(df, include_hq_sensor=True)
    first = next(iter(labels), None)
    radius = f"{config['radius_m'] * 1000:g} mm" if config else "the configured radius"
    doc.heading("Plane-fit coverage")
    doc.para(f"The plane fit uses every reference point within {radius} of a point. One pixel of a 640x480 image "
             "spans z/f metres (about 1.9 mm at 1 m, 3.7 mm at 2 m, 5.6 mm at 3 m for f = 537 px), so a 5 mm ball "
             "holds about 21 points at 1 m, 5 at 2 m and only the point itself beyond about 2.7 m: there the "
             "plane is undefined and the point is excluded (counted below, and plotted against depth). The "
             "distance is taken to the closest denoised point, so noise much larger than a pixel is under-estimated.",
             cls="note")
    rows = []
    for (ds, ref), part in f[f["method_key"] == first].groupby(["dataset", "reference"], sort=True):
        v = part.groupby("metric")["value"]
        used, few, deg = v.sum().get("plane_fit_n", 0), v.sum().get("plane_fit_excluded_few", 0), \
            v.sum().get("plane_fit_excluded_degenerate", 0)
        tot = used + few + deg
        rows.append([ds, ref, _fmt(v.mean().get("n_reference", np.nan), 0),
                     _fmt(v.median().get("plane_fit_neighbors_median", np.nan), 1),
                     _fmt(100 * used / tot if tot else np.nan, 1), _fmt(100 * few / tot if tot else np.nan, 1),
                     _fmt(100 * deg / tot if tot else np.nan, 1)])
    if rows:
        doc.table(["dataset", "reference", "reference pixels / frame", "median neighbours", "used (%)",
                   "too few neighbours (%)", "line-like (%)"], rows)
        doc.para(f"Scored points of the {labels[first]} column; other columns differ only where a method leaves "
                 "pixels empty.", cls="note")


def _published_rows(df: pd.DataFrame, labels: dict[str, str]) -> list[list[str]]:
    """The seed report's Table I numbers under the columns of the same methods (one column per slot)."""
    slot_of = {k: table_i_slot(df.loc[df["method_key"] == k, "method"].iloc[0]) for k in labels}
    owner = {slot: k for k, slot in slot_of.items()}     # several versions of a method: the last column shows them
    rows = []
    for pub in PUBLISHED:
        cells = []
        for k in labels:
            slot = slot_of[k]
            v = pub["values"].get(TABLE_I[slot][0]) if slot is not None else None
            cells.append(_fmt(v) if v is not None and owner.get(slot) == k else "")
        rows.append([pub["label"]] + cells)
    return rows


def _header_section(doc: _Doc, df: pd.DataFrame, datasets: pd.DataFrame, config: dict | None) -> None:
    n_datasets = len(datasets)
    n_frames = df[["dataset_checksum", "frame"]].drop_duplicates().shape[0]
    doc.heading("depthbench leaderboard", 1)
    cfg_text = (f"plane-fit radius {config['radius_m'] * 1000:g} mm, at least {config['min_neighbors']} neighbours, "
                f"depth bins of {config['depth_bin_m']:g} m" if config else "metric parameters: see results.json")
    doc.para(f"{n_datasets} dataset(s), {n_frames} frames, {len(method_labels(df))} method(s); {len(df)} result rows "
             f"(schema version {R.SCHEMA_VERSION}); {cfg_text}. Rebuilt from `results.parquet` by "
             "`depthbench bench report`.")


def _depth_section(doc: _Doc, df: pd.DataFrame, config: dict | None) -> None:
    doc.heading("Error against depth")
    for ref in ("hq", "truth"):
        curves = depth_curves(df, ref)
        if curves.empty:
            continue
        labels = method_labels(df[df["reference"] == ref], include_hq_sensor=(ref == "truth"))
        title = f"against the {'HQ reference' if ref == 'hq' else 'truth'}, pooled over frames, by reference depth"
        png = plots.error_vs_depth(curves, labels, title=title)
        if ref == "hq":
            doc.para(f"Bins of {config['depth_bin_m'] if config else 0.25:g} m by reference depth, pooled over frames "
                     f"(MAE weighted by pixels, plane-fit RMSE by points); bins with less than "
                     f"{MIN_BIN_SHARE:.1%} of a method's pixels are left out.", cls="note")
        doc.figure(f"error_vs_depth_{ref}.png", png,
                   f"Error against depth ({'HQ reference' if ref == 'hq' else 'truth'})")


def _qualitative_section(doc: _Doc, df: pd.DataFrame, root: Path, datasets: pd.DataFrame, max_shown: int) -> None:
    doc.heading("Qualitative comparison")
    labels_all = method_labels(df)
    shown = 0
    for r in datasets.itertuples():
        if shown >= max_shown:
            break
        inputs = R.load_npz(R.preview_path(root, r.dataset_checksum))
        if inputs is None:
            continue
        denoised = {}
        for k in df.loc[(df["dataset_checksum"] == r.dataset_checksum), "method_key"].unique():
            p = R.load_npz(R.preview_path(root, r.dataset_checksum, k))
            if p is not None:
                denoised[str(p["method_key"])] = p["depth"]
        labels = {k: v for k, v in labels_all.items() if k in denoised}
        frame = int(inputs["frame"])
        png = plots.qualitative(inputs, denoised, labels, title=f"{r.dataset} (sequence {r.sequence}), frame {frame}")
        doc.figure(f"qualitative_{r.dataset_checksum[:16]}.png", png,
                   f"{r.dataset}, frame {frame}: depth and shaded normals")
        shown += 1
    if shown == 0:
        doc.para("No depth previews in this results folder (the table alone cannot draw depth images).", cls="note")


def _inventory_section(doc: _Doc, df: pd.DataFrame, datasets: pd.DataFrame) -> None:
    """The methods (keys, versions) and the datasets (sequence, frames, checksum) of the table."""
    doc.heading("Methods")
    mrows = []
    for k, label in method_labels(df, include_hq_sensor=True).items():
        m = df.loc[df["method_key"] == k].iloc[0]
        mrows.append([label, f"`{k}`", str(m["method_version"])])
    doc.table(["column", "method key (name@version(parameters))", "version"], mrows)
    doc.heading("Datasets")
    drows = []
    for r in datasets.itertuples():
        n = df.loc[df["dataset_checksum"] == r.dataset_checksum, "frame"].nunique()
        drows.append([r.dataset, r.sequence, str(n), f"`{r.dataset_checksum[:16]}`"])
    doc.table(["dataset", "sequence", "frames", "checksum"], drows)


def _not_in_paper(provenance: dict) -> str:
    options = provenance.get("not_in_paper") or []
    return f"; not in the paper: {', '.join(f'`{o}`' for o in options)}" if options else ""


def _learned_section(doc: _Doc, df: pd.DataFrame, root: Path) -> None:
    """Each learned column's weights, training manifest and config (from ``results.json``), and a loud
    warning for any column scored on its own training or validation data."""
    try:
        methods = {m["key"]: m for m in R.read_manifest(root).get("methods", [])}
    except Exception:   # noqa: BLE001 - the table alone still makes a leaderboard
        return
    labels = method_labels(df)
    learned = [(labels[k], methods[k]) for k in labels if k in methods and methods[k].get("learned")]
    if not learned:
        return
    doc.heading("Learned methods")
    rows, warnings = [], []
    for label, m in learned:
        w, p = m.get("weights") or {}, m.get("provenance") or {}
        rows.append([label, f"`{Path(str(w.get('file', '?'))).name}` sha256 `{str(w.get('sha256', ''))[:16]}`",
                     f"{p.get('train_manifest', '?')} (`{str(p.get('train_manifest_sha256') or '')[:16]}`)",
                     f"`{p.get('config_file', '?')}`" + _not_in_paper(p), ", ".join(p.get("trained_on", [])) or "?"])
        if p.get("WARNING"):
            warnings.append(f"**WARNING: {label} was {p['WARNING']}; its numbers there are not a test score.**")
    doc.table(["column", "weights", "training manifest", "config", "trained / validated on"], rows)
    for text in warnings:
        doc.para(text, cls="warning")
    doc.para("A learned method is refused on datasets of its own training or validation split (same dataset "
             "checksum or same source recording), unless explicitly allowed; allowed columns are marked above.",
             cls="note")


DEFINITIONS = (
    "**MSE / RMSE / MAE**: over pixels valid in both the output and the reference, inside the ROI, in "
    "millimetres (SSDD's comparison). **Plane-fit RMSE** (DDD): for each reference point, the least-squares "
    "plane through all reference points within the radius; the distance from that plane to the closest "
    "point of the denoised cloud; RMSE over the points (too few neighbours or line-like neighbourhoods are "
    "excluded and counted). **Fill rate**: share of reference-valid ROI pixels the method leaves valid. "
    "**Normal angle**: mean angle between central-difference normals of output and reference.")


def build_report(df: pd.DataFrame, *, root: Path, config: dict | None, n_boot: int = 2000, seed: int = 0,
                 max_qualitative: int = 4) -> _Doc:
    """The whole leaderboard document of the results table ``df`` (previews read from ``root``)."""
    datasets = df[["dataset", "dataset_checksum", "sequence"]].drop_duplicates().sort_values("dataset")
    doc = _Doc()
    _header_section(doc, df, datasets, config)
    _summary_section(doc, df, "hq", n_boot=n_boot, seed=seed)
    if (df["reference"] == "truth").any():
        _summary_section(doc, df, "truth", n_boot=n_boot, seed=seed)
        _noref_section(doc, df, n_boot=n_boot, seed=seed)
    _interior_section(doc, df, n_boot=n_boot, seed=seed)
    if (df["reference"] == "truth").any():
        _ranking_section(doc, df, n_boot=n_boot, seed=seed)
    from bench.table_i import table_i_section

    table_i_section(doc, df, n_boot=n_boot, seed=seed)
    _sequence_section(doc, df)
    _depth_section(doc, df, config)
    _qualitative_section(doc, df, root, datasets, max_qualitative)
    _coverage_section(doc, df, config)
    _inventory_section(doc, df, datasets)
    _learned_section(doc, df, root)
    doc.heading("Definitions")
    doc.para(DEFINITIONS)
    return doc


def write_report(results_dir: str | Path, *, table: pd.DataFrame | None = None, n_boot: int = 2000, seed: int = 0,
                 max_qualitative: int = 4) -> ReportPaths:
    """Write ``leaderboard.md``, ``leaderboard.html`` and ``figures/`` into ``results_dir``.

    Args:
        results_dir: a results folder (its ``results.parquet`` is read unless ``table`` is given).
        table: the results table, when the caller has it.
        n_boot: bootstrap resamples; ``seed``: their random seed.
        max_qualitative: datasets shown in the qualitative figure (the first ones by name).

    Returns:
        :class:`ReportPaths`.
    """
    root = Path(results_dir)
    df = R.load_results(root) if table is None else table
    if df.empty:
        raise R.ResultsFormatError(f"{root}: the results table has no rows")
    try:
        meta = R.read_manifest(root)
    except R.ResultsFormatError:
        meta = None
    doc = build_report(df, root=root, config=meta["metrics"] if meta else None, n_boot=n_boot, seed=seed,
                       max_qualitative=max_qualitative)
    figs_dir = root / "figures"
    with staged_directory(figs_dir, force=True, what="figures folder") as tmp:
        for name, png in doc.figures.items():
            (tmp / name).write_bytes(png)
    md_path, html_path = root / "leaderboard.md", root / "leaderboard.html"
    atomic_write_text(md_path, doc.markdown())
    atomic_write_text(html_path, doc.html())
    return ReportPaths(md_path, html_path, [figs_dir / name for name in doc.figures])
