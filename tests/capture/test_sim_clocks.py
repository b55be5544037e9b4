"""Must-show: clock effects are exact. Every timestamp in frames.csv follows the declared
offset, drift and frame rate (recomputed here from truth.json with the documented formulas),
dropped frames leave gaps in the frame numbers, and the time shift means what it says."""
from __future__ import annotations

import json

import numpy as np
import pytest

from capture.session import open_session
from capture.sim.clocks import DEFAULT_MAX_SHIFT_US, Clock, draw_shift_us, frame_schedule
from capture.truth import read_truth
from tests.capture.simkit import session


@pytest.fixture(scope="module", params=["people_declared", "people_undeclared"])
def sim(request):
    root = session(request.param)
    return open_session(root), read_truth(root)


def _clock(truth, sensor) -> Clock:
    c = truth.clock(sensor)
    return Clock(**{k: c[k] for k in Clock.__dataclass_fields__})


def test_timestamps_follow_the_clock_formulas(sim):
    s, t = sim
    for sensor in t.sensors:
        c = t.clock(sensor)
        tt = t.frames(sensor)
        k = tt["frame_number"].to_numpy() - c["first_frame_number"]
        period = 1e6 / c["fps"]
        dev_rate, host_rate = 1 + c["device_drift_ppm"] * 1e-6, 1 + c["host_drift_ppm"] * 1e-6
        scene = np.rint((c["phase_us"] + k * period) / dev_rate).astype(np.int64)
        assert np.array_equal(scene, tt["scene_time_us"].to_numpy())
        dev = c["device_offset_us"] + np.rint(dev_rate * scene).astype(np.int64)
        jitter = tt["host_jitter_us"].to_numpy()
        assert np.abs(jitter).max() <= c["host_jitter_bound_us"]
        host = c["host_offset_us"] + np.rint(host_rate * scene).astype(np.int64) + jitter
        for stream in ("depth", "color"):
            df = s.frames(sensor, stream)
            assert np.array_equal(df["frame_number"].to_numpy(), tt["frame_number"].to_numpy())
            assert np.array_equal(df["device_timestamp_us"].to_numpy(), dev)
            assert np.array_equal(df["host_timestamp_us"].to_numpy(), host)
        # the nominal frame rate shows in the device timestamps: steps of whole periods
        steps = np.diff(df["device_timestamp_us"].to_numpy()) / period
        assert np.allclose(steps, np.round(steps), atol=0.01) and np.all(np.round(steps) >= 1)


def test_time_shift_definition(sim):
    """An instant the HQ stamps t is stamped t + a + b (t - t0) by the LQ (jitter aside)."""
    s, t = sim
    m = t.info["time_shift_model"]
    hq, lq = t.clock("hq"), t.clock("lq")
    tt = t.frames("lq")
    tau = tt["scene_time_us"].to_numpy()
    t_hq = hq["host_offset_us"] + tau  # the HQ host clock is the reference (rate 1)
    t_lq = s.frames("lq", "depth")["host_timestamp_us"].to_numpy() - tt["host_jitter_us"].to_numpy()
    predicted = t_hq + t.time_shift_at_us(t_hq)
    assert np.abs(t_lq - predicted).max() <= 1.0
    assert m["t0_us"] == hq["host_offset_us"] and m["a_us"] == t.time_shift_us
    assert m["b"] == pytest.approx(400e-6)
    assert abs(t.time_shift_us) <= DEFAULT_MAX_SHIFT_US  # drawn (the session declares none)


def test_drawn_time_shifts_stay_inside_aligns_search_range():
    """Shifts the simulator draws keep a margin inside align's search range that the shift estimates' errors
    (0.4-1.1 ms on clean seeds) do not cross, so align's edge rule (a best shift within a quarter step of the
    range's end is refused) cannot refuse a drawn one: session 7's seed 26 was drawn 1.1 ms inside +-60 ms,
    estimated 0.65 ms further out, and refused. They still spread uniformly over the rest of the range."""
    from align.time_shift import DEFAULT_RANGE_US, DEFAULT_STEP_US

    rng, raw_rng = np.random.default_rng(26), np.random.default_rng(26)
    shifts = np.array([draw_shift_us(rng) for _ in range(20_000)])
    raw = raw_rng.integers(-60_000, 60_001, 20_000)  # the draw over the whole range, as before the margin
    inside = np.abs(raw) <= DEFAULT_MAX_SHIFT_US
    assert np.array_equal(shifts[inside], raw[inside])  # a seed whose shift was inside keeps its session
    assert rng.integers(0, 2**62) == raw_rng.integers(0, 2**62)  # the stream goes on as before
    edge = DEFAULT_RANGE_US - 0.25 * DEFAULT_STEP_US  # the nearest to the end align accepts
    assert edge - np.abs(shifts).max() >= 3 * 1100  # three times the largest estimate error seen
    assert np.abs(shifts).max() > DEFAULT_MAX_SHIFT_US - 100  # the range is used up to its bound
    q = np.quantile(shifts, [0.1, 0.25, 0.5, 0.75, 0.9])
    assert np.allclose(q, DEFAULT_MAX_SHIFT_US * np.array([-0.8, -0.5, 0.0, 0.5, 0.8]), atol=1500)  # uniform


def test_dropped_frames_leave_gaps(sim):
    s, t = sim
    total_dropped = 0
    for sensor in t.sensors:
        fn = s.frames(sensor, "depth")["frame_number"].to_numpy()
        dropped = t.clock(sensor)["dropped_frame_numbers"]
        expected = set(range(fn[0], fn[-1] + 1)) - set(fn.tolist())
        assert expected == {d for d in dropped if fn[0] < d < fn[-1]}
        assert s.manifest["sensors"][sensor]["streams"]["depth"]["dropped_frames"] == len(dropped)
        total_dropped += len(dropped)
    assert total_dropped >= 3  # 25 % of ~30 frames


def test_declared_clock_facts():
    declared = json.loads((session("people_declared") / "session.json").read_text())
    undeclared = json.loads((session("people_undeclared") / "session.json").read_text())
    assert declared["clock_facts"]["drift_ppm"] == 400.0
    assert declared["effects"] == {"clock_drift_ppm": 400.0, "frame_drop_rate": 0.25}
    assert "drift_ppm" not in undeclared["clock_facts"] and undeclared["effects"] == {}
    assert "time_shift_us" not in declared["clock_facts"]  # alignment must find it
    assert declared["time_base"] == "host"


def test_drift_shows_in_host_rate():
    s, t = open_session(session("people_declared")), read_truth(session("people_declared"))
    tau = t.frames("lq")["scene_time_us"].to_numpy()
    host = s.frames("lq", "depth")["host_timestamp_us"].to_numpy()
    slope = np.polyfit(tau, host - t.frames("lq")["host_jitter_us"].to_numpy(), 1)[0]
    assert slope - 1 == pytest.approx(400e-6, abs=2e-6)


def test_schedule_rate_and_jitter_bound():
    c = Clock(fps=15.0, first_frame_number=7, phase_us=1000.0, device_offset_us=5, device_drift_ppm=-20.0,
              host_offset_us=10**15, host_drift_ppm=0.0, host_jitter_bound_us=1000, drop_rate=0.0)
    sch = frame_schedule(c, seconds=10.0, rng=np.random.default_rng(0))
    assert len(sch) == 150 and sch.frame_number[0] == 7
    rate = (len(sch) - 1) / ((sch.scene_time_us[-1] - sch.scene_time_us[0]) * 1e-6)
    assert rate == pytest.approx(15.0 * (1 - 20e-6), rel=1e-7)
    assert np.abs(sch.host_jitter_us).max() <= 1000 and np.abs(sch.host_jitter_us).max() > 900
