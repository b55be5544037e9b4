"""The simulator effects added for the alignment loop: depth offset, rolling shutter, duplicated
frames, HQ colour lens -- each where it should be, checked against truth/ and a global-shutter twin."""
from __future__ import annotations

import json
from functools import lru_cache

import numpy as np
import pytest

from capture.session import open_session
from capture.sim import simulate
from capture.sim.clocks import Clock, frame_schedule
from capture.sim.effects import ROLLING_SHUTTER_BAND_MS
from capture.truth import read_truth

BASE = dict(rig="lq-hq", scene="people", seconds=0.2, seed=7, scale=0.25, progress=False, workers=1,
            time_shift_us=0)


@lru_cache(maxsize=None)
def _session(tmp_root: str, name: str, **effects):
    root = f"{tmp_root}/{name}"
    simulate(root, undeclared=True, effects=effects or None, **BASE)
    return root


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return str(tmp_path_factory.mktemp("simfx"))


def test_depth_offset_and_scale_on_lq_only(root):
    """Against the same session without the effect (same noise): z' = 1.01 z + 40 mm, to the 1 mm depth unit."""
    r, clean = _session(root, "offset", depth_offset_mm=40.0, depth_scale=1.01), _session(root, "global")
    s, c = open_session(r), open_session(clean)
    for sensor, scale, offset in (("lq", 1.01, 0.040), ("hq", 1.0, 0.0)):
        fn = int(s.frames(sensor, "depth")["frame_number"][0])
        meas, base = s.read_depth(sensor, fn), c.read_depth(sensor, fn)
        ok = np.isfinite(meas) & np.isfinite(base)
        assert ok.mean() > 0.3
        assert np.abs(meas[ok] - (scale * base[ok] + offset)).max() <= 0.0011 + 0.01 * 0.0005
    assert json.loads((s.root / "session.json").read_text())["effects"] == {}


def test_rolling_shutter_moves_only_the_rows_away_from_the_middle(root):
    g, rs = _session(root, "global"), _session(root, "rolling", rolling_shutter_ms=30.0)
    sg, sr = open_session(g), open_session(rs)
    diff_rows = np.zeros(0)
    for fn in sg.frames("lq", "color")["frame_number"][:4]:
        a = sg.read_color("lq", int(fn)).astype(int)
        b = sr.read_color("lq", int(fn)).astype(int)
        assert np.array_equal(sg.read_depth("lq", int(fn)), sr.read_depth("lq", int(fn)), equal_nan=True)
        d = np.abs(a - b).sum(axis=(1, 2))
        diff_rows = d if diff_rows.size == 0 else diff_rows + d
    H = diff_rows.size
    bands = int(np.ceil(30.0 / ROLLING_SHUTTER_BAND_MS))
    edges = np.linspace(0, H, bands + 1).round().astype(int)
    mid = bands // 2  # an odd number of bands: the middle band is exposed at the frame's instant
    assert bands % 2 == 1 and diff_rows[edges[mid]:edges[mid + 1]].sum() == 0
    assert diff_rows[: edges[1]].sum() > 0 and diff_rows[edges[-2]:].sum() > 0


def test_duplicated_frames_repeat_bytes_and_truth(root):
    r = _session(root, "dups", frame_duplicate_rate=0.4)
    s, t = open_session(r), read_truth(r)
    f = s.frames("lq", "depth")
    same = (f["sha256"].to_numpy()[1:] == f["sha256"].to_numpy()[:-1])
    assert same.any()
    tf = t.frames("lq")
    st = tf["scene_time_us"].to_numpy()
    assert np.array_equal(st[1:] == st[:-1], same)  # a duplicate carries its predecessor's instant
    assert np.all(np.diff(f["host_timestamp_us"].to_numpy()) > 0)  # with its own stamp
    assert not (s.frames("hq", "depth")["sha256"].to_numpy()[1:] == s.frames("hq", "depth")["sha256"].to_numpy()[:-1]).any()


def test_duplicate_schedule_leaves_everything_else_alone():
    c = Clock(fps=30.0, first_frame_number=1, phase_us=0.0, device_offset_us=0, device_drift_ppm=0.0,
              host_offset_us=0, host_drift_ppm=0.0, host_jitter_bound_us=500, drop_rate=0.1)
    a = frame_schedule(c, seconds=3.0, rng=np.random.default_rng(5))
    b = frame_schedule(Clock(**{**c.__dict__, "duplicate_rate": 0.2}), seconds=3.0, rng=np.random.default_rng(5))
    assert np.array_equal(a.frame_number, b.frame_number) and np.array_equal(a.host_timestamp_us, b.host_timestamp_us)
    dup = b.source_frame_number != b.frame_number
    assert 0.05 < dup.mean() < 0.4 and not dup[0]
    assert np.array_equal(b.duplicated_frame_numbers, b.frame_number[dup])


def test_hq_lens_on_hq_colour_only(root):
    r = _session(root, "hqlens", hq_distortion_k1=0.1)
    t = read_truth(r)
    assert t.info["sensors"]["hq"]["color_intrinsics"]["coeffs"][0] == 0.1
    assert t.info["sensors"]["hq"]["depth_intrinsics"]["distortion_model"] == "none"
    m = json.loads((open_session(r).root / "session.json").read_text())
    assert m["sensors"]["hq"]["streams"]["color"]["intrinsics"]["distortion_model"] == "none"  # undeclared
