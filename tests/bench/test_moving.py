"""The bench's moving stratum: pixels whose depth changed by more than 1 cm since the previous frame."""
from __future__ import annotations

import numpy as np
import pytest

from align.dataset import AlignedDataset, AlignedDatasetWriter
from bench.metrics import MetricConfig, moving_errors, moving_mask
from bench.runner import run_benchmark
from tests.bench.conftest import SMALL_CONFIG
from tests.bench.helpers import K_SMALL, Shift, scene_depth


def _direct_mask(depth, previous, threshold):
    out = np.zeros(depth.shape, bool)
    for v in range(depth.shape[0]):
        for u in range(depth.shape[1]):
            a, b = float(depth[v, u]), float(previous[v, u])
            if np.isfinite(a) and np.isfinite(b) and a > 0 and b > 0:
                out[v, u] = abs(a - b) > threshold
    return out


def _direct_errors(pred, ref, roi, moving):
    e = [(float(pred[v, u]) - float(ref[v, u])) * 1000.0 for v in range(ref.shape[0]) for u in range(ref.shape[1])
         if moving[v, u] and roi[v, u] and np.isfinite(pred[v, u]) and np.isfinite(ref[v, u]) and ref[v, u] > 0]
    return len(e), float(np.mean(np.square(e))), float(np.mean(np.abs(e)))


def test_moving_mask_and_errors_match_a_direct_loop():
    rng = np.random.default_rng(3)
    prev = rng.uniform(1.0, 2.0, (9, 11)).astype(np.float32)
    now = prev + rng.choice([0.0, 0.005, -0.02, 0.03], prev.shape).astype(np.float32)
    now[0, :4] = np.nan
    prev[2, 5] = np.nan
    now[3, 3] = 0.0
    m = moving_mask(now, prev, threshold_m=0.01)
    assert (m == _direct_mask(now, prev, 0.01)).all() and 0 < m.sum() < m.size
    pred = now + rng.normal(0, 0.004, now.shape).astype(np.float32)
    pred[4, :] = np.nan
    roi = np.ones(now.shape, bool)
    roi[:, :2] = False
    got = moving_errors(pred, now, m, roi)
    n, mse, mae = _direct_errors(pred, now, roi, m)
    assert got["n_moving"] == n and got["mse_moving_mm2"] == pytest.approx(mse) and got["mae_moving_mm"] == pytest.approx(mae)
    assert np.isnan(moving_errors(pred, now, None, roi)["mse_moving_mm2"])
    with pytest.raises(Exception, match="must be non-negative"):
        MetricConfig(moving_threshold_m=-1.0)


def _moving_dataset(root):
    """Truth: a square that moves 3 cm per frame on a background that moves 0.5 mm (never 'moving')."""
    rng = np.random.default_rng(0)
    meta = {"name": "mv", "lq_intrinsics": K_SMALL.to_dict(), "time_shift_us": 0, "T_lq_hq": np.eye(4).tolist()}
    with AlignedDatasetWriter(root, meta) as w:
        for i in range(3):
            t = scene_depth(K_SMALL) + np.float32(0.0005 * i)
            t[20:40, 10 + 5 * i:30 + 5 * i] -= np.float32(0.3 + 0.03 * i)
            lq = (t + rng.normal(0, 0.004, t.shape)).astype(np.float32)
            ref = (t + rng.normal(0, 0.001, t.shape)).astype(np.float32)
            roi = np.zeros(t.shape, bool)
            roi[5:-5, 5:-5] = True
            w.add_frame(lq, ref, roi=roi, truth=t, lq_frame=i, hq_frame=i, lq_timestamp_us=i * 33_333)
    return root


def test_bench_scores_the_moving_stratum_from_the_truth_against_a_direct_formula(tmp_path):
    ds = AlignedDataset(_moving_dataset(tmp_path / "mv"))
    t = run_benchmark([ds.root], ["raw", Shift()], tmp_path / "r", config=SMALL_CONFIG, jobs=1,
                      progress=False).table
    rows = t[t["bin_lo_m"].isna() & (t["method"] == "raw")].set_index(["frame", "reference", "metric"])["value"]
    assert np.isnan(rows[(0, "truth", "mse_moving_mm2")])          # no previous frame
    for i in (1, 2):
        fr = ds.frame(i)
        moving = _direct_mask(ds.truth(i), ds.truth(i - 1), 0.01)   # from the truth, for both references
        assert 0 < moving.sum() < 0.5 * moving.size
        for ref_name, ref in (("truth", fr.truth), ("hq", fr.reference)):
            n, mse, mae = _direct_errors(fr.lq_depth, ref, fr.roi, moving)
            assert rows[(i, ref_name, "n_moving")] == n
            assert rows[(i, ref_name, "mse_moving_mm2")] == pytest.approx(mse, rel=1e-9)
            assert rows[(i, ref_name, "mae_moving_mm")] == pytest.approx(mae, rel=1e-9)
        assert rows[(i, "truth", "n_moving")] < rows[(i, "truth", "n_valid")]
    board = (tmp_path / "r" / "leaderboard.md").read_text()
    assert "MSE, moving pixels (mm²)" in board and "MAE, moving pixels (mm)" in board
