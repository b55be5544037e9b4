"""The whole-ROI truth scoring (reference ``truth_roi``) derived from the two truth strata equals a direct
computation over every ROI pixel with truth, frame by frame and per depth bin; Table I shows it."""
from __future__ import annotations

import numpy as np
import pytest

from align.dataset import AlignedDataset
from bench.runner import run_benchmark
from bench.table_i import table_i_rows
from bench.truth_roi import FRAME_WEIGHTS, TRUTH_ROI, truth_roi_rows, with_truth_roi
from tests.bench.conftest import SMALL_CONFIG
from tests.bench.helpers import Shift
from tests.bench.test_truth_strata import _silhouette_dataset


def _direct(pred, truth, roi):
    """Errors (mm) over the ROI pixels where truth and prediction are finite and > 0, pixel by pixel."""
    e = [(float(pred[v, u]) - float(truth[v, u])) * 1000.0 for v in range(truth.shape[0])
         for u in range(truth.shape[1]) if roi[v, u] and np.isfinite(pred[v, u]) and pred[v, u] > 0
         and np.isfinite(truth[v, u]) and truth[v, u] > 0]
    return np.array(e)


def test_truth_roi_equals_a_direct_computation_over_every_roi_pixel(tmp_path):
    ds = AlignedDataset(_silhouette_dataset(tmp_path / "sil"))
    res = run_benchmark([ds.root], ["raw", Shift()], tmp_path / "r", config=SMALL_CONFIG, jobs=1,
                        progress=False, report=False)
    derived = truth_roi_rows(res.table)
    assert set(derived["metric"]) == set(FRAME_WEIGHTS) | {"rmse_mm", "fill_rate"}
    assert "hq_sensor" not in set(derived["method"])      # it has no silhouette stratum: no whole-ROI rows
    rows = derived[derived["bin_lo_m"].isna()].set_index(["method", "frame", "metric"])["value"]
    bins = derived[derived["bin_lo_m"].notna()].set_index(["method", "frame", "bin_lo_m", "metric"])["value"]
    for i in range(len(ds)):
        fr = ds.frame(i)
        roi_truth = fr.roi & np.isfinite(fr.truth) & (fr.truth > 0)
        for method in ("raw", "test_shift"):
            pred = fr.lq_depth + (np.float32(0.005) if method == "test_shift" else np.float32(0))
            e = _direct(pred, fr.truth, fr.roi)
            assert rows[(method, i, "n_valid")] == e.size and rows[(method, i, "n_reference")] == roi_truth.sum()
            assert rows[(method, i, "mse_mm2")] == pytest.approx(np.mean(e * e), rel=1e-9)
            assert rows[(method, i, "rmse_mm")] == pytest.approx(np.sqrt(np.mean(e * e)), rel=1e-9)
            assert rows[(method, i, "mae_mm")] == pytest.approx(np.mean(np.abs(e)), rel=1e-9)
            assert rows[(method, i, "bias_mm")] == pytest.approx(np.mean(e), rel=1e-9, abs=1e-9)
            assert rows[(method, i, "fill_rate")] == pytest.approx(e.size / roi_truth.sum(), rel=1e-12)
            if i > 0:   # moving: the truth changed by > 1 cm since the previous frame
                prev = ds.frame(i - 1).truth
                moving = fr.roi & np.isfinite(prev) & (prev > 0) & (np.abs(fr.truth - prev) > 0.01)
                em = _direct(pred, fr.truth, moving)
                assert em.size > 0 and rows[(method, i, "n_moving")] == em.size
                assert rows[(method, i, "mse_moving_mm2")] == pytest.approx(np.mean(em * em), rel=1e-9)
                assert rows[(method, i, "mae_moving_mm")] == pytest.approx(np.mean(np.abs(em)), rel=1e-9)
            w = SMALL_CONFIG.depth_bin_m
            for lo in np.unique(np.floor(fr.truth[roi_truth].astype(np.float64) / w)):
                eb = _direct(pred, fr.truth, roi_truth & (np.floor(fr.truth.astype(np.float64) / w) == lo))
                key = (method, i, round(lo * w, 9))
                assert bins[key + ("n_valid",)] == eb.size
                if eb.size:
                    assert bins[key + ("mae_mm",)] == pytest.approx(np.mean(np.abs(eb)), rel=1e-9)
                    assert bins[key + ("rmse_mm",)] == pytest.approx(np.sqrt(np.mean(eb * eb)), rel=1e-9)
        # the whole ROI is not the reference's pixels: the silhouettes make it worse here
        t = res.table
        shared = t[(t.reference == "truth") & (t.method == "raw") & (t.frame == i) & (t.metric == "mse_mm2")
                   & t.bin_lo_m.isna()]["value"].item()
        assert rows[("raw", i, "mse_mm2")] > 1.5 * shared
    full = with_truth_roi(res.table)
    assert len(full) == len(res.table) + len(derived) and with_truth_roi(full) is full
    header, table, _ = table_i_rows(full, n_boot=50)
    labels = [r[0] for r in table]
    whole = table[labels.index("suite, vs truth on the whole ROI: MSE (mm²)")]
    mean = rows.xs("mse_mm2", level="metric").xs("raw", level="method").mean()
    assert whole[header.index("Raw")].startswith(f"{mean:.2f} [")
    assert "suite, vs truth on the reference's pixels: MSE (mm²)" in labels
    assert not any(TRUTH_ROI in l for l in labels)   # rows are labelled in words
