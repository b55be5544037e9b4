"""The truth columns score the HQ reference's own pixels (like with like); the ROI pixels without a reference
are their own stratum ("silhouettes / no reference", reference ``truth_noref``), scored against the truth only;
the leaderboard says whether the reference ranks the methods as the truth does on the shared pixels."""
from __future__ import annotations

import numpy as np
import pytest

from align.dataset import AlignedDataset, AlignedDatasetWriter
from bench.masks import truth_strata
from bench.summary import decided_wrongly, noref_share, ranking_check
from bench.runner import run_benchmark
from tests.bench.conftest import SMALL_CONFIG
from tests.bench.helpers import K_SMALL, Shift, box_scene


def _silhouette_dataset(root):
    """Truth: a near box on a slanted wall; the reference loses a 2-px band around the box's outline (the
    silhouettes a coarse HQ sensor cannot resolve) and a few random pixels, and the LQ depth is worst there."""
    rng = np.random.default_rng(5)
    meta = {"name": "sil", "lq_intrinsics": K_SMALL.to_dict(), "time_shift_us": 0, "T_lq_hq": np.eye(4).tolist()}
    with AlignedDatasetWriter(root, meta) as w:
        for i in range(4):
            t, box = box_scene(i, step_m=0.5)
            grown = np.zeros(t.shape, bool)
            grown[16:44, 20 + 2 * i:54 + 2 * i] = True
            band = grown & ~np.pad(box[2:-2, 2:-2], 2)
            ref = (t + rng.normal(0, 0.001, t.shape)).astype(np.float32)
            ref[band | (rng.random(t.shape) < 0.03)] = np.nan
            ref[0, :] = 0.0   # "no measurement" written as 0 counts as none
            lq = (t + rng.normal(0, 0.004, t.shape)).astype(np.float32)
            lq[band] += np.float32(0.05) * rng.standard_normal(int(band.sum())).astype(np.float32)
            roi = np.zeros(t.shape, bool)
            roi[12:48, 15:65] = True
            w.add_frame(lq, ref, roi=roi, truth=t, lq_frame=i, hq_frame=i, lq_timestamp_us=i * 33_333)
    return root


def _direct(pred, ref, pixels):
    """MSE (mm^2) and the count over ``pixels`` (bool) where both are finite and > 0: a plain loop."""
    e = [(float(pred[v, u]) - float(ref[v, u])) * 1000.0 for v in range(ref.shape[0]) for u in range(ref.shape[1])
         if pixels[v, u] and np.isfinite(pred[v, u]) and np.isfinite(ref[v, u]) and ref[v, u] > 0 and pred[v, u] > 0]
    return float(np.mean(np.square(e))), len(e)


def test_truth_columns_score_the_reference_pixels_and_the_rest_is_its_own_stratum(tmp_path):
    ds = AlignedDataset(_silhouette_dataset(tmp_path / "sil"))
    res = run_benchmark([ds.root], ["raw", Shift()], tmp_path / "r", config=SMALL_CONFIG, jobs=1,
                        progress=False)
    t = res.table
    rows = t[t["bin_lo_m"].isna()].set_index(["method", "frame", "reference", "metric"])["value"]
    shares = []
    for i in range(len(ds)):
        fr = ds.frame(i)
        has_ref = np.zeros(fr.roi.shape, bool)   # direct: reference finite and > 0, pixel by pixel
        for v in range(has_ref.shape[0]):
            for u in range(has_ref.shape[1]):
                x = float(fr.reference[v, u])
                has_ref[v, u] = np.isfinite(x) and x > 0
        shared, noref = fr.roi & has_ref, fr.roi & ~has_ref
        assert 0.05 < noref.sum() / fr.roi.sum() < 0.5
        strata = truth_strata(fr.truth, fr.reference)
        in_roi = {k: fr.roi & np.isfinite(v) for k, v in strata.items()}
        assert np.array_equal(in_roi["truth_noref"], noref & np.isfinite(fr.truth))
        assert np.array_equal(in_roi["truth"], shared & np.isfinite(fr.truth))
        for method in ("raw", "test_shift"):
            pred = fr.lq_depth + (np.float32(0.005) if method == "test_shift" else np.float32(0))
            for name, pixels in (("truth", shared), ("truth_noref", noref)):
                mse, n = _direct(pred, fr.truth, pixels)
                assert rows[(method, i, name, "n_valid")] == n
                assert rows[(method, i, name, "mse_mm2")] == pytest.approx(mse, rel=1e-9)
            assert rows[(method, i, "truth_noref", "mse_mm2")] > 3 * rows[(method, i, "truth", "mse_mm2")]
        # the HQ sensor (the reference against the truth) is scored on the shared pixels only
        mse, n = _direct(fr.reference, fr.truth, shared)
        assert rows[("hq_sensor", i, "truth", "mse_mm2")] == pytest.approx(mse, rel=1e-9)
        assert ("hq_sensor", i, "truth_noref", "mse_mm2") not in rows.index
        n_ref = {k: rows[("raw", i, k, "n_reference")] for k in ("truth", "truth_noref")}
        assert n_ref["truth_noref"] == noref.sum() and n_ref["truth"] == shared.sum()
        shares.append(noref.sum() / fr.roi.sum())
    np.testing.assert_allclose(noref_share(t).to_numpy(), shares, rtol=1e-12)
    board = (tmp_path / "r" / "leaderboard.md").read_text()
    assert "Silhouettes / no reference" in board and "The HQ reference scores none of these pixels" in board
    assert "on the HQ reference's pixels" in board
    assert "Does the HQ reference rank the methods as the truth does?" in board
    assert "Silhouettes / no reference" in (tmp_path / "r" / "leaderboard.html").read_text()


def test_ranking_check_finds_an_order_the_reference_gets_wrong(tmp_path):
    """On the shared pixels the reference agrees with the truth; a flip made only on the reference's values
    is found, and the paired interval of the flipped pair excludes zero in both scorings."""
    ds = AlignedDataset(_silhouette_dataset(tmp_path / "sil"))
    res = run_benchmark([ds.root], ["raw", Shift()], tmp_path / "r", config=SMALL_CONFIG, jobs=1, progress=False,
                        report=False)
    t = res.table
    check = ranking_check(t, n_boot=200)
    for metric in ("mse_mm2", "rmse_mm"):
        assert check[metric]["same"], check[metric]["order"]
        (a, b, d), = check[metric]["pairs"]
        assert d["hq"][0] < 0 and d["truth"][0] < 0     # raw is better than raw + 5 mm in both
        assert d["truth"][2] < 0                         # and the interval says so
        assert check[metric]["wrong"] == []
    # swap the two methods' values against the HQ reference only: now the orders differ
    t2 = t.copy()
    hq = t2["reference"] == "hq"
    keys = sorted(t2["method_key"].unique())
    raw_key = next(k for k in keys if k.startswith("raw"))
    shift_key = next(k for k in keys if k.startswith("test_shift"))
    is_raw, is_shift = hq & (t2["method_key"] == raw_key), hq & (t2["method_key"] == shift_key)
    t2.loc[is_raw, "method_key"], t2.loc[is_shift, "method_key"] = shift_key, raw_key
    flipped = ranking_check(t2, n_boot=200)
    for metric in ("mse_mm2", "rmse_mm"):
        assert not flipped[metric]["same"]
        (a, b, d), = flipped[metric]["pairs"]
        assert np.sign(d["hq"][0]) != np.sign(d["truth"][0]) and d["hq"][1] > 0 and d["truth"][2] < 0
        assert flipped[metric]["wrong"] == [(a, b)]     # both clear of zero: a contradiction
    # the same flip with either scoring's interval straddling zero: within noise, not a contradiction
    (a, b, d), = flipped["mse_mm2"]["pairs"]
    assert decided_wrongly(d["hq"], d["truth"])
    assert not decided_wrongly((d["hq"][0], -abs(d["hq"][1]), abs(d["hq"][2])), d["truth"])
    assert not decided_wrongly(d["hq"], (d["truth"][0], -abs(d["truth"][1]), abs(d["truth"][2])))
