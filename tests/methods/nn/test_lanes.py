"""Inference lanes (methods/nn/lanes.py): independent passes side by side, each lane on its own torch threads."""
import threading

import pytest
import torch

from methods.nn.lanes import ENV, Lanes
from tests.methods.nn.helpers import torch_threads


@pytest.fixture
def two_threads():
    with torch_threads(2):
        yield


def test_lanes_run_side_by_side_on_their_own_threads_in_inference_mode(two_threads):
    lanes = Lanes(2, 1)
    meet = threading.Barrier(2, timeout=20)      # both items must be running at once to pass it

    def fn(item):
        meet.wait()
        return item * 10, threading.current_thread().name, torch.get_num_threads(), torch.is_inference_mode_enabled()

    try:
        out = lanes.map(fn, [3, 4])
    finally:
        lanes.close()
    assert [o[0] for o in out] == [30, 40]                              # in the items' order
    assert all(o[1].startswith("lane") and o[2] == 1 and o[3] for o in out)
    assert len({o[1] for o in out}) == 2 and torch.get_num_threads() == 2   # the caller's threads untouched


def test_one_lane_runs_in_the_callers_thread_with_its_grad_mode(two_threads):
    lanes = Lanes.split(4, device="cuda")
    assert (lanes.lanes, lanes.threads) == (1, 2)
    here = threading.current_thread().name
    out = lanes.map(lambda i: (i, threading.current_thread().name, torch.is_inference_mode_enabled()), [1, 2, 3])
    assert out == [(1, here, False), (2, here, False), (3, here, False)]


@pytest.mark.parametrize("threads, jobs, env, expect", [
    (2, 2, None, (2, 1)), (2, 3, None, (2, 1)), (2, 1, None, (1, 2)), (4, 2, None, (2, 2)),
    (1, 2, None, (1, 1)), (2, 2, "0", (1, 2)), (2, 2, "off", (1, 2)), (2, 2, "1", (2, 1))])
def test_split_shares_the_threads_out(threads, jobs, env, expect, monkeypatch):
    if env is None:
        monkeypatch.delenv(ENV, raising=False)
    else:
        monkeypatch.setenv(ENV, env)
    with torch_threads(threads):
        lanes = Lanes.split(jobs)
    assert (lanes.lanes, lanes.threads) == expect


def test_a_forked_child_starts_its_own_threads(two_threads):
    lanes = Lanes(2, 1)
    try:
        assert lanes.map(lambda i: i + 1, [1, 2]) == [2, 3]
        first = lanes._executor()
        lanes._pid = -1                                  # as a forked child sees its parent's pool
        assert lanes._executor() is not first
        assert lanes.map(lambda i: i + 1, [1, 2]) == [2, 3]
    finally:
        lanes.close()


def test_bad_sizes_are_refused():
    with pytest.raises(ValueError, match="at least 1"):
        Lanes(0, 1)
