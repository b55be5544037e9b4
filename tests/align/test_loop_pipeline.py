"""The loop inside `align_session` on a simulated session with two undeclared effects (LQ lens k1,
duplicated LQ frames), checked against truth/ afterwards; and nothing added to a clean session."""
from __future__ import annotations

import json

import numpy as np
import pytest

from align.pipeline import align_session
from capture.camera import Transform
from capture.truth import read_truth
from tests.align.conftest import simulate_session


@pytest.fixture(scope="module")
def lens_dups(tmp_path_factory):
    root = simulate_session(tmp_path_factory.mktemp("loop") / "lens_dups", seed=11, time_shift_us=-32_033,
                            undeclared=True, effects={"distortion_k1": 0.1, "frame_duplicate_rate": 0.1})
    out = root.parent / "aligned"
    res = align_session(root, out, progress=False)
    return root, out, res, json.loads((out / "aligned.json").read_text())


def test_two_undeclared_effects_named_and_measured(lens_dups):
    root, out, res, meta = lens_dups
    found = {e["name"]: e for e in meta["effects"] if e["source"] == "found"}
    assert set(found) == {"lens_lq_k1", "duplicated_frames"}, meta["loop"]["stages"]
    k1 = found["lens_lq_k1"]
    lo, hi = k1["interval95"]["k1"]
    assert lo <= 0.1 <= hi and abs(k1["params"]["k1"] - 0.1) <= 0.01
    assert k1["z"] > meta["loop"]["threshold_z"] and k1["delta_bic"] < 0
    # the aligned dataset is warped through the found lens, and T_lq_hq is right again
    assert meta["lq_intrinsics"]["coeffs"][0] == pytest.approx(k1["params"]["k1"])
    truth = read_truth(root)
    dt, dr = res.T_lq_hq.error_to(Transform.from_list(truth.info["T_lq_hq"]))
    assert dt < 0.005, dt  # 49 mm without the loop (issue 12's table: 59 mm)
    # the final model (pose, shift, k1) was refitted on the photometrically refined tracks
    assert meta["loop"]["refined_fit"].startswith("refitted on"), meta["loop"]["refined_fit"]
    # duplicated LQ frames: counted exactly, and no pair uses one
    t_frames = truth.frames("lq")
    st = t_frames["scene_time_us"].to_numpy()
    n_dup = int((st[1:] == st[:-1]).sum())
    assert found["duplicated_frames"]["params"]["count"] >= n_dup  # depth and colour streams both counted
    pairs = (out / "pairs.csv").read_text()
    assert "duplicates its predecessor" in pairs


def test_reported_pose_deviation_is_the_loops_where_the_loop_replaced_the_pose(lens_dups):
    """``T_lq_hq_std`` belongs to the ``T_lq_hq`` written: the loop's final fit's covariance (with the time shift's
    shared error), not the base fit's, which fitted the pose without the lens (about 10 mm here); it covers the
    truth. The shift's deviation: the loop's fit and the shared error in quadrature."""
    from align.extrinsics import pose_std
    from align.loop.loop import POSE_MODEL_ERROR
    from align.time_shift import MODEL_ERROR_US

    root, _, res, meta = lens_dups
    fl = res.views["lq"].loop.features
    t_sd, r_sd = pose_std(fl.covariance)
    assert meta["T_lq_hq_std"]["translation_mm"] == pytest.approx(1e3 * t_sd)
    assert meta["T_lq_hq_std"]["rotation_deg"] == pytest.approx(r_sd)
    assert t_sd > pose_std(fl.cov)[0]  # the shared shift error and the pose's are in
    assert np.all(np.diag(fl.covariance)[3:6] >= np.diag(fl.cov)[3:6] + POSE_MODEL_ERROR[1] ** 2 * (1 - 1e-9))
    assert t_sd < 0.5 * res.fit.translation_std_m
    dt, _ = res.T_lq_hq.error_to(Transform.from_list(read_truth(root).info["T_lq_hq"]))
    assert dt < 3 * t_sd, (dt, t_sd)
    assert res.shift.std_us == pytest.approx(np.hypot(1e3 * np.sqrt(fl.cov[6, 6]), MODEL_ERROR_US))


def test_report_shows_the_loop(lens_dups):
    _, out, _, meta = lens_dups
    md = (out / "report.md").read_text()
    assert "## Effects the alignment model needed" in md and "`lens_lq_k1`" in md
    assert "on the photometrically refined keypoints, chosen on the detected ones: refitted on" in md
    assert (out / "figures" / "loop_lens_lq_k1.png").is_file()
    assert "warped HQ reference vs truth, MAE" in md  # simulated: end-to-end error before/after
    assert meta["loop"]["heldout_features_px"]["after"]["median_abs"] < meta["loop"]["heldout_features_px"]["before"]["median_abs"]


def test_end_to_end_error_is_that_of_the_references_written(lens_dups):
    """One way to warp: the loop's end-to-end error against truth, computed for the dataset's own
    geometry and options, equals the error of the references the aligned dataset holds for the same
    pairs (up to its 0.1 mm storage step) -- the edge rule and the motion step included."""
    from types import SimpleNamespace

    from align.dataset import AlignedDataset
    from align.loop.report import end_to_end
    from align.pair_reference import ReferenceOptions
    from align.pipeline import TruthSource, pair_setup
    from capture.camera import Intrinsics
    from capture.session import open_session

    root, out, res, meta = lens_dups
    ds = AlignedDataset(out)
    setup = pair_setup(open_session(root), lq="lq", hq="hq")
    K = Intrinsics.from_dict(meta["lq_intrinsics"])
    geometry = {"T_lq_hq": res.T_lq_hq, "K_lq": K, "shift_us": float(res.shift.time_shift_us), "drift_ppm": 0.0,
                "t0_us": 0.0}
    loop = SimpleNamespace(base=geometry, lq_duplicates=[], correct_lq_depth=lambda d: d,
                           **{k: v for k, v in geometry.items() if k not in ("t0_us",)})
    opts = ReferenceOptions.from_meta(meta)
    assert opts.reference_edges == "footprint-fg"  # the default
    e2e = end_to_end(setup, None, loop, TruthSource(root, "lq"), pairs=10, reference=opts,
                     background=res.background)["after"]
    rows = {(int(r["hq_frame"]), int(r["lq_frame"])): int(r["index"]) for r in ds.rows}
    matched = [(rows[f], mae) for f, mae in zip(map(tuple, e2e["frames"]), e2e["frame_mae_mm"]) if f in rows]
    assert len(matched) >= 0.8 * len(e2e["frames"])  # pairs the dataset dropped or paired otherwise: few
    for index, mae in matched:
        ref, tr = ds.reference(index), ds.truth(index)
        m = np.isfinite(ref) & np.isfinite(tr)
        assert 1e3 * np.mean(np.abs(ref[m] - tr[m])) == pytest.approx(mae, abs=0.1)
    midpoint = end_to_end(setup, None, loop, TruthSource(root, "lq"), pairs=10,
                          reference=ReferenceOptions(reference_edges="midpoint"))["after"]
    # the two ways differ, beyond the 0.1 mm the match above allows: this one is align's (the -fg rules keep the
    # background outside the ROI that strict masked, so over all pixels its RMSE is near the midpoint warp's)
    diff = np.abs(np.subtract(midpoint["frame_mae_mm"], e2e["frame_mae_mm"]))
    assert np.mean(diff) > 0.3, (diff, midpoint["reference_rmse_mm"], e2e["reference_rmse_mm"])


def test_an_effect_with_look_alikes_keeps_the_search_fit_and_its_interval_covers(tmp_path):
    """A small LQ lens (k1 0.02, seed 21, 4 s) is accepted with the HQ lens as its look-alike: the final model is not
    refitted on the refined keypoints (that narrowed the interval about 2.8x and moved the estimate from +11 % to
    +18 %: it covered the truth on 0 of seeds 21-23, 3 of 3 without it; session 12's recheck note)."""
    root = simulate_session(tmp_path / "k1s", seed=21, seconds=4.0, undeclared=True, effects={"distortion_k1": 0.02})
    align_session(root, tmp_path / "a", progress=False, workers=1, report=False)
    meta = json.loads((tmp_path / "a" / "aligned.json").read_text())
    found = {e["name"]: e for e in meta["effects"] if e["source"] == "found"}
    assert found["lens_lq_k1"]["look_alikes"] == ["lens_hq_k1"], meta["loop"]["stages"]
    assert meta["loop"]["refined_fit"].startswith("not run: lens_lq_k1 accepted with look-alikes")
    lo, hi = found["lens_lq_k1"]["interval95"]["k1"]
    assert lo <= 0.02 <= hi
