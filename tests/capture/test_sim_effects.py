"""Each effect shows up where it should, declared or not, and nowhere else."""
from __future__ import annotations

import json

import numpy as np
import pytest

from capture.session import open_session
from capture.sim import SimulationError, parse_effects
from capture.sim.scene import PLANES_WALL_M
from capture.truth import read_truth
from tests.capture.simkit import pairs, session


@pytest.mark.parametrize("name", ["lens_declared", "lens_undeclared"])
def test_depth_scale_multiplies_lq_depth(name):
    ratios = []
    for _, meas, truth in pairs(name, "lq"):
        ok = np.isfinite(meas) & np.isfinite(truth)
        ratios.append(meas[ok] / truth[ok])
    assert np.median(np.concatenate(ratios)) == pytest.approx(1.1, abs=0.002)
    for _, meas, truth in pairs(name, "hq"):  # the HQ is untouched
        ok = np.isfinite(meas) & np.isfinite(truth)
        assert np.median(meas[ok] / truth[ok]) == pytest.approx(1.0, abs=0.001)


def test_declared_effects_in_session_json():
    m = json.loads((session("lens_declared") / "session.json").read_text())
    assert m["effects"] == {"depth_scale": 1.1, "distortion_k1": -0.2}
    for stream in ("depth", "color"):
        K = m["sensors"]["lq"]["streams"][stream]["intrinsics"]
        assert K["distortion_model"] == "opencv" and K["coeffs"] == [-0.2, 0.0, 0.0, 0.0, 0.0]
    assert m["sensors"]["hq"]["streams"]["depth"]["intrinsics"]["distortion_model"] == "none"


def test_undeclared_effects_only_in_truth():
    root = session("lens_undeclared")
    text = (root / "session.json").read_text()
    m = json.loads(text)
    assert m["effects"] == {}
    assert m["sensors"]["lq"]["streams"]["depth"]["intrinsics"]["distortion_model"] == "none"
    assert "-0.2" not in text and "1.1" not in text.replace('"1.1.', "")  # no trace of the values
    t = read_truth(root)
    assert t.effects == {"depth_scale": 1.1, "distortion_k1": -0.2}
    assert t.info["effects_declared"] is False and t.info["effect_target"] == "lq"
    assert t.intrinsics("lq").coeffs[0] == -0.2  # truth knows the camera as rendered


def _wall_y(root, intrinsics_from_session: bool) -> np.ndarray:
    """World y of LQ truth points on the back wall, unprojected with the session's (or truth's)
    intrinsics; the wall is the plane y = PLANES_WALL_M."""
    s, t = open_session(root), read_truth(root)
    K = s.intrinsics("lq") if intrinsics_from_session else t.intrinsics("lq")
    fn = int(t.frames("lq")["frame_number"][0])
    z = t.depth("lq", fn)
    pts = t.T_world("lq").apply(K.depth_to_points(z).reshape(-1, 3))
    y = pts[:, 1]
    return y[np.isfinite(y) & (np.abs(y - PLANES_WALL_M) < 0.3) & (pts[:, 2] > 0.3)]


def test_distortion_is_in_the_rendered_lq_images():
    # declared: the session's intrinsics (with k1) put every wall pixel back on the wall
    y = _wall_y(session("lens_declared"), True)
    assert y.size > 1000 and np.abs(y - PLANES_WALL_M).max() < 0.002
    # undeclared: the session says "none", and unprojecting with it bends the wall
    y = _wall_y(session("lens_undeclared"), True)
    assert np.abs(y - PLANES_WALL_M).max() > 0.01  # 2 cm at the corners for k1 = -0.2
    assert np.abs(_wall_y(session("lens_undeclared"), False) - PLANES_WALL_M).max() < 0.002


def test_frame_drop_rate_declared_and_undeclared():
    for name, declared in (("people_declared", True), ("people_undeclared", False)):
        m = json.loads((session(name) / "session.json").read_text())
        assert ("frame_drop_rate" in m["effects"]) is declared
        assert read_truth(session(name)).effects["frame_drop_rate"] == 0.25


@pytest.mark.parametrize("bad, fragment", [
    (["focus=1"], "unknown effect"), (["depth_scale"], "expected NAME=VALUE"), (["depth_scale=abc"], "not a number"),
    (["depth_scale=7"], "within [0.5, 2]"), (["frame_drop_rate=0.1", "frame_drop_rate=0.2"], "more than once"),
    (["clock_drift_ppm=nan"], "within"),
])
def test_bad_effects(bad, fragment):
    with pytest.raises(SimulationError, match=None) as exc:
        parse_effects(bad)
    assert fragment in str(exc.value) and "\n" not in str(exc.value)


def test_no_effects_means_clean_truth():
    t = read_truth(session("planes"))
    assert t.effects == {} and t.info["drift_ppm"] == 0.0
    m = json.loads((session("planes") / "session.json").read_text())
    assert m["effects"] == {} and "drift_ppm" not in m["clock_facts"]
