"""Away from the reference's depth edges (``hq_interior`` / ``truth_interior``): the pixel set against a direct
loop, the bench's rows on it, and the reason it exists: a reference that reads mixes at silhouettes orders an
edge-mixing method above a better one on all its pixels, and as the truth does away from its edges."""
from __future__ import annotations

import numpy as np
import pytest

from align.dataset import AlignedDataset, AlignedDatasetWriter
from bench.masks import EDGE_FILL_PX, EDGE_REL, EDGE_WIDTH_PX, depth_edge_mask, interior_strata
from bench.runner import run_benchmark
from bench.summary import edge_share, ranking_check
from tests.bench.conftest import SMALL_CONFIG
from tests.bench.helpers import K_SMALL, Shift, Smooth, box_scene


def _edges_by_loop(ref, *, width=EDGE_WIDTH_PX, rel=EDGE_REL, fill=EDGE_FILL_PX):
    """The documented rule pixel by pixel: fill holes from the farthest neighbour, mark 3x3 spans over ``rel``,
    keep reference pixels within ``width`` (Euclidean) of a mark."""
    H, W = ref.shape
    d = [[float(ref[v, u]) if np.isfinite(ref[v, u]) and ref[v, u] > 0 else 0.0 for u in range(W)] for v in range(H)]
    nb = lambda v, u: [(a, b) for a in range(v - 1, v + 2) for b in range(u - 1, u + 2) if 0 <= a < H and 0 <= b < W]
    for _ in range(fill):
        d = [[d[v][u] or max(d[a][b] for a, b in nb(v, u)) for u in range(W)] for v in range(H)]
    marks = []
    for v in range(H):
        for u in range(W):
            vals = [d[a][b] for a, b in nb(v, u) if d[a][b] > 0]
            if d[v][u] > 0 and max(vals) - min(vals) > rel * d[v][u]:
                marks.append((v, u))
    out = np.zeros((H, W), bool)
    for v in range(H):
        for u in range(W):
            if d[v][u] > 0 and np.isfinite(ref[v, u]) and ref[v, u] > 0:
                out[v, u] = any((v - a) ** 2 + (u - b) ** 2 <= width ** 2 + 1e-9 for a, b in marks)
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_depth_edge_mask_matches_a_direct_loop(seed):
    rng = np.random.default_rng(seed)
    ref = np.full((24, 30), 2.0, np.float32) + rng.normal(0, 0.002, (24, 30)).astype(np.float32)
    r0, c0 = rng.integers(4, 10, 2)
    ref[r0:r0 + 8, c0:c0 + 9] = 1.0 + rng.normal(0, 0.002)     # a near box
    ref[r0 - 2:r0 + 10, c0 + 9:c0 + 11] = np.nan                # its far-side band masked
    ref[rng.random(ref.shape) < 0.04] = np.nan                  # dropouts
    ref[0, :3] = 0.0                                            # "none" written as 0
    for width in (1.0, 2.0):
        got = depth_edge_mask(ref, width_px=width)
        want = _edges_by_loop(ref, width=width)
        assert np.array_equal(got, want)
    assert 0.05 < depth_edge_mask(ref).mean() < 0.5              # the box's outline, not the dropouts
    s = interior_strata(ref, ref + np.float32(0.01))
    assert np.array_equal(np.isfinite(s["hq_interior"]), np.isfinite(ref) & (ref > 0) & ~depth_edge_mask(ref))
    assert np.array_equal(np.isfinite(s["truth_interior"]), np.isfinite(s["hq_interior"]))


def test_depth_edge_mask_rejects_bad_options():
    from bench.errors import MetricInputError

    with pytest.raises(MetricInputError, match="width_px >= 0"):
        depth_edge_mask(np.ones((4, 4), np.float32), width_px=-1)


def _mixing_dataset(root):
    """Truth: a near box on a slanted wall; the LQ depth is the truth plus 0.3 mm noise. The reference is the
    truth, except on a 1-px ring either side of the box's outline where it reads the 3x3 mean of the truth (a
    footprint's mix), as the 3x3 mean method does there."""
    from scipy.ndimage import uniform_filter

    rng = np.random.default_rng(3)
    meta = {"name": "mix", "lq_intrinsics": K_SMALL.to_dict(), "time_shift_us": 0, "T_lq_hq": np.eye(4).tolist()}
    with AlignedDatasetWriter(root, meta) as w:
        for i in range(5):
            t, box = box_scene(i, step_m=0.4)
            ring = uniform_filter(box.astype(float), 3) % 1 > 0
            ref = np.where(ring, uniform_filter(t.astype(np.float64), 3), t).astype(np.float32)
            lq = (t + rng.normal(0, 0.0003, t.shape)).astype(np.float32)
            roi = np.zeros(t.shape, bool)
            roi[10:50, 12:70] = True
            w.add_frame(lq, ref, roi=roi, truth=t, lq_frame=i, hq_frame=i, lq_timestamp_us=i * 33_333)
    return root


def test_interior_rows_and_the_ranking_they_fix(tmp_path):
    ds = AlignedDataset(_mixing_dataset(tmp_path / "mix"))
    res = run_benchmark([ds.root], [Smooth(), Shift(mm=2.0)], tmp_path / "r", config=SMALL_CONFIG, jobs=1,
                        progress=False)
    t = res.table
    rows = t[t["bin_lo_m"].isna()].set_index(["method", "frame", "reference", "metric"])["value"]
    for i in range(len(ds)):
        fr = ds.frame(i)
        inner = fr.roi & np.isfinite(fr.reference) & ~_edges_by_loop(fr.reference)
        pred = fr.lq_depth + np.float32(0.002)
        for ref_name, ref in (("hq_interior", fr.reference), ("truth_interior", fr.truth)):
            e = (pred[inner].astype(np.float64) - ref[inner]) * 1000
            assert rows[("test_shift", i, ref_name, "n_valid")] == inner.sum()
            assert rows[("test_shift", i, ref_name, "mse_mm2")] == pytest.approx(np.mean(e ** 2), rel=1e-9)
        e = (fr.reference[inner].astype(np.float64) - fr.truth[inner]) * 1000
        assert rows[("hq_sensor", i, "truth_interior", "mse_mm2")] == pytest.approx(np.mean(e ** 2), abs=1e-9)
        assert ("hq_sensor", i, "hq_interior", "mse_mm2") not in rows.index
    shares = edge_share(t).to_numpy()
    assert ((shares > 0.05) & (shares < 0.5)).all()
    # on all the reference's pixels the mixing ring makes the 3x3 mean win against the reference, lose against truth
    everywhere = ranking_check(t, n_boot=200)
    for metric in ("mse_mm2", "rmse_mm"):
        (a, b, d), = everywhere[metric]["pairs"]
        assert everywhere[metric]["wrong"] == [(a, b)], d
    interior = ranking_check(t, stratum="interior", n_boot=200)
    for metric in ("mse_mm2", "rmse_mm"):
        assert interior[metric]["same"] and interior[metric]["wrong"] == []
        (a, b, d), = interior[metric]["pairs"]
        assert np.sign(d["hq"][0]) == np.sign(d["truth"][0]) and (d["truth"][1] > 0 or d["truth"][2] < 0)
    board = (tmp_path / "r" / "leaderboard.md").read_text()
    assert "## Away from the reference's depth edges (the ranking)" in board
    assert "**Away from the reference's depth edges (the leaderboard's ranking)**: MSE: **yes**" in board
    assert "**On all the reference's pixels**: MSE: **no**" in board
    assert "**Ranking** (MSE against the HQ reference, away from its depth edges; best first): test_smooth < test_shift" in board
