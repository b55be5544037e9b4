"""The Table I section: the seed's seven columns, its two published rows, ours under each."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from bench.table_i import COLUMNS, table_i_rows


def _table():
    rng = np.random.default_rng(0)
    rows = []
    for method in ("raw", "bilateral", "ddd", "ddrnet_refine"):
        for ref in ("hq", "truth"):
            for frame in range(4):
                for metric in ("plane_fit_rmse_mm", "mse_mm2", "rmse_mm"):
                    rows.append(dict(method=method, method_key=f"{method}@1()", method_version="1", reference=ref,
                                     bin_lo_m=np.nan, dataset_checksum="c", frame=frame, metric=metric,
                                     value=float(rng.uniform(1, 100))))
    return pd.DataFrame(rows)


def test_table_i_has_the_seeds_columns_and_rows_with_our_means_beneath():
    df = _table()
    header, rows, classes = table_i_rows(df, n_boot=50)
    assert header == ["row", "Raw", "BF", "RGF", "DDRNet", "DDD", "SSDD (UNet)", "SSDD (LSTM)"]
    assert [c[0] for c in COLUMNS] == header[1:]
    labels = [r[0] for r in rows]
    assert labels[0].startswith("seed: DDD [4]") and classes[0] == "published"
    assert rows[0][1:] == ["–", "73.25", "81.35", "239.06", "58.95", "–", "–"]
    ssdd = labels.index(next(l for l in labels if l.startswith("seed: SSDD [5]")))
    assert rows[ssdd][1:] == ["57.22", "56.39", "49.49", "57.08", "84.07", "31.61", "21.02"]
    mse_truth = rows[labels.index("suite, vs truth on the reference's pixels: MSE (mm²)")]
    for col, method in ((1, "raw"), (2, "bilateral"), (5, "ddd")):
        v = df[(df.method == method) & (df.reference == "truth") & (df.metric == "mse_mm2")]["value"].mean()
        assert mse_truth[col].startswith(f"{v:.2f} [")
    assert mse_truth[3] == mse_truth[4] == "–"  # RGF and DDRNet not run (ddrnet_refine is not the DDRNet column)
    assert classes.count("published") == 2 and len(rows) == 2 + 2 + 4
    pytest.importorskip("bench.report")
