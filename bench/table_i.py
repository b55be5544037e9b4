"""The seed report's Table I beside the suite's own: the same seven columns, the same two rows.

Table I of the seed report prints, for Raw, BF, RGF, DDRNet, DDD, SSDD (UNet) and SSDD (LSTM), one
row from DDD's paper (plane-fit RMSE in mm, their 70-pair evaluation set) and one from SSDD's paper
("MSE (mm)" as printed). This section lays the suite's numbers out the same way, each under the
published row it corresponds to: the plane-fit RMSE (the seed's RMSE row), and the MSE in mm²
together with the RMSE in mm (the seed's "MSE (mm)" unit fits neither exactly), against the HQ
reference and, for simulated data, against the simulator's truth. Against the truth there are two
pixel sets: the HQ reference's own pixels (reference ``truth``, like with like with the reference rows)
and the whole ROI (``truth_roi``, :mod:`bench.truth_roi`: also the silhouettes / no-reference pixels;
MSE and RMSE only, the plane fit does not combine across the strata). Cells are means over frames with
95 % bootstrap intervals (:func:`bench.summary.bootstrap_summary`). The DDRNet column is the
denoising net alone (``ddrnet``), as DDD's comparison ran it; ``ddrnet_refine`` and other methods
are in the summary tables above.
"""
from __future__ import annotations

import pandas as pd

from bench.summary import bootstrap_summary, frame_values
from bench.truth_roi import TRUTH_ROI, with_truth_roi

#: The seed's columns: label, the suite's method name, the key of the published values.
COLUMNS = (("Raw", "raw", "raw"), ("BF", "bilateral", "bf"), ("RGF", "rolling_guidance", "rgf"),
           ("DDRNet", "ddrnet", "ddrnet"), ("DDD", "ddd", "ddd"), ("SSDD (UNet)", "ssdd_unet", "ssdd_unet"),
           ("SSDD (LSTM)", "ssdd_lstm", "ssdd_lstm"))

#: Our rows under each published row: (label, reference, metric).
OURS = {
    "plane_fit_rmse_mm": (("suite, vs HQ reference: plane-fit RMSE (mm)", "hq", "plane_fit_rmse_mm"),
                          ("suite, vs truth on the reference's pixels: plane-fit RMSE (mm)", "truth",
                           "plane_fit_rmse_mm")),
    "mse_mm2": (("suite, vs HQ reference: MSE (mm²)", "hq", "mse_mm2"),
                ("suite, vs HQ reference: RMSE (mm)", "hq", "rmse_mm"),
                ("suite, vs truth on the reference's pixels: MSE (mm²)", "truth", "mse_mm2"),
                ("suite, vs truth on the reference's pixels: RMSE (mm)", "truth", "rmse_mm"),
                ("suite, vs truth on the whole ROI: MSE (mm²)", TRUTH_ROI, "mse_mm2"),
                ("suite, vs truth on the whole ROI: RMSE (mm)", TRUTH_ROI, "rmse_mm")),
}


def column_keys(df: pd.DataFrame) -> list[str | None]:
    """The method key shown in each of the seed's columns (the last version of that method), or None."""
    out = []
    for _, method, _ in COLUMNS:
        keys = df.loc[df["method"] == method, ["method_key", "method_version"]].drop_duplicates()
        out.append(str(keys.sort_values("method_version").iloc[-1]["method_key"]) if len(keys) else None)
    return out


def table_i_rows(df: pd.DataFrame, *, n_boot: int = 2000, seed: int = 0) -> tuple[list[str], list[list[str]], list[str]]:
    """``(header, rows, row classes)`` of the side-by-side table (classes ``published`` / ``""``)."""
    from bench.report import PUBLISHED, _cell, _fmt

    keys = column_keys(df)
    df = with_truth_roi(df)
    summaries = {}
    for ref in ("hq", "truth", TRUTH_ROI):
        if (df["reference"] == ref).any():
            wide = frame_values(df, ref)
            summaries[ref] = (bootstrap_summary(wide, n_boot=n_boot, seed=seed), len(wide))
    rows, classes = [], []
    for pub in PUBLISHED:
        rows.append([f"seed: {pub['label']}"] + [_fmt(pub["values"].get(p)) if p in pub["values"] else "–"
                                                  for _, _, p in COLUMNS])
        classes.append("published")
        for label, ref, metric in OURS.get(pub["metric"], ()):
            if ref not in summaries:
                continue
            s, n = summaries[ref]
            rows.append([label] + [_cell(s, metric, k, n_total=n) if k else "–" for k in keys])
            classes.append("")
    return ["row"] + [c[0] for c in COLUMNS], rows, classes


def table_i_section(doc, df: pd.DataFrame, *, n_boot: int = 2000, seed: int = 0) -> None:
    """Append the section to a :class:`bench.report._Doc`."""
    header, rows, classes = table_i_rows(df, n_boot=n_boot, seed=seed)
    doc.heading("Table I: the seed report's numbers beside ours")
    doc.table(header, rows, row_classes=classes)
    doc.para("Italic rows: the seed report's Table I (other data, other sensors, other error definitions; DDD's row "
             "is their plane-fit RMSE, SSDD's their \"MSE (mm)\"). Plain rows: this leaderboard, means over frames "
             "with 95 % bootstrap intervals, under the published row they correspond to. \"vs truth on the "
             "reference's pixels\" scores the pixels the HQ reference rows score; \"on the whole ROI\" adds the "
             "ROI pixels without a reference (silhouettes, the edge rule's mask), exact from the two strata. "
             "DDRNet is the denoising net alone, as DDD's comparison ran it; `ddrnet_refine` (with the refinement net) is in the summary "
             "above. –: the method was not run.", cls="note")
