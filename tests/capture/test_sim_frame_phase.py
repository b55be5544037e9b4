"""The simulator's frame phase: how far apart in scene time the LQ and HQ frames fall is set
deterministically (issue 12's motion item needs sessions whose pairs are 0, 3 or 7 ms apart),
checked against the clock formulas of :mod:`capture.sim.clocks` recomputed here; nothing else of
the plan changes; bad values are one-line errors with exit status 2."""
from __future__ import annotations

from dataclasses import asdict

import numpy as np
import pytest

from capture.sim import SimulationError
from capture.sim.simulator import make_plan
from tests.conftest import assert_one_line_error

PLAN = dict(rig="lq-hq", scene="planes", seconds=2.0, seed=5, effects=None, undeclared=False, time_shift_us=None,
            static=False, scale=0.1, lq_fps=30.0, hq_fps=30.0)


def _apart_us(plan) -> np.ndarray:
    """Per LQ frame: its scene time minus that of the latest HQ frame at or before it (µs)."""
    hq, lq = plan.schedules["hq"].scene_time_us, plan.schedules["lq"].scene_time_us
    lq = lq[lq >= hq[0]]
    return lq - hq[np.searchsorted(hq, lq, side="right") - 1]


@pytest.mark.parametrize("phase_us, expect_us", [(0, 0), (3000, 3000), (7000, 7000), (-7000, 33333 - 7000)])
def test_frame_phase_sets_how_far_apart_the_frames_fall(phase_us, expect_us):
    plan = make_plan(**PLAN, frame_phase_us=phase_us)
    apart = _apart_us(plan)
    # the devices' own drift (+-20 ppm each) moves the phase by at most 40 ppm of the session, plus rounding
    tol = 40e-6 * 2e6 + 2
    assert apart.size >= 50
    assert np.all(np.abs(apart - expect_us) <= tol) or (expect_us == 0 and np.all(
        np.minimum(np.abs(apart), np.abs(apart - 33333)) <= tol))


def test_frame_phase_changes_nothing_else():
    drawn = make_plan(**PLAN)
    set_ = make_plan(**PLAN, frame_phase_us=7000)
    for sid in ("hq", "lq"):
        a, b = asdict(drawn.clocks[sid]), asdict(set_.clocks[sid])
        if sid == "lq":
            assert a.pop("phase_us") != b.pop("phase_us")
        assert a == b
    assert np.array_equal(drawn.schedules["hq"].scene_time_us, set_.schedules["hq"].scene_time_us)
    assert np.array_equal(drawn.schedules["lq"].host_jitter_us, set_.schedules["lq"].host_jitter_us)
    # the drawn phase is not the set one: the option does something
    assert not np.allclose(_apart_us(drawn), 7000, atol=100)


@pytest.mark.parametrize("bad", [40000, -33400, float("nan"), "x"])
def test_bad_frame_phase(bad):
    with pytest.raises(SimulationError, match="--frame-phase-ms: .* not within one LQ frame period"):
        make_plan(**PLAN, frame_phase_us=bad)


def test_cli_frame_phase_error(cli, tmp_path):
    r = cli("capture", "simulate", "--out", tmp_path / "x", "--frame-phase-ms", "34", "--no-progress")
    assert_one_line_error(r, "--frame-phase-ms", "34 ms", "33.33 ms")
    assert not (tmp_path / "x").exists()
