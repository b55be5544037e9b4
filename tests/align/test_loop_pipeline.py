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
    # duplicated LQ frames: counted exactly, and no pair uses one
    t_frames = truth.frames("lq")
    st = t_frames["scene_time_us"].to_numpy()
    n_dup = int((st[1:] == st[:-1]).sum())
    assert found["duplicated_frames"]["params"]["count"] >= n_dup  # depth and colour streams both counted
    pairs = (out / "pairs.csv").read_text()
    assert "duplicates its predecessor" in pairs


def test_report_shows_the_loop(lens_dups):
    _, out, _, meta = lens_dups
    md = (out / "report.md").read_text()
    assert "## Effects the alignment model needed" in md and "`lens_lq_k1`" in md
    assert (out / "figures" / "loop_lens_lq_k1.png").is_file()
    assert "warped HQ reference vs truth, MAE" in md  # simulated: end-to-end error before/after
    assert meta["loop"]["heldout_features_px"]["after"]["median_abs"] < meta["loop"]["heldout_features_px"]["before"]["median_abs"]
