"""``depthbench align`` on a session with a missing or unreadable frame file fails at once, before the
time-shift and extrinsic fit: one line naming the file, exit 2, nothing printed before it, nothing
written, the session unchanged."""
from __future__ import annotations

import os

import pytest

from tests.capture.inproc_cli import run_inproc
from tests.capture.sessionkit import tree_digest, write_source
from tests.conftest import assert_one_line_error


@pytest.fixture
def no_fit(monkeypatch):
    """The fit (the long work) must not start."""
    import align.pipeline

    def fit_started(*args, **kwargs):
        raise AssertionError("the fit started before the frame files were checked")

    monkeypatch.setattr(align.pipeline, "pair_setup", fit_started)
    monkeypatch.setattr(align.pipeline, "fit_pair", fit_started)


@pytest.mark.parametrize("damage", ["missing", "folder"])
def test_missing_hq_frame_fails_before_the_fit(tmp_path, capfd, no_fit, damage):
    root = tmp_path / "S"
    write_source(root, n=6)
    frame = root / "hq" / "depth" / "00000004.png"
    frame.unlink()
    if damage == "folder":
        frame.mkdir()
    before = tree_digest(root)
    r = run_inproc(capfd, "align", root, "--out", tmp_path / "A")     # progress bars and INFO logs on
    assert_one_line_error(r, str(frame), "missing" if damage == "missing" else "not a regular file")
    assert r.stdout == ""
    assert tree_digest(root) == before and sorted(os.listdir(tmp_path)) == ["S"]


@pytest.mark.parametrize("command", ["methods", "bench"])
def test_dataset_with_a_missing_frame_fails_before_any_frame_is_processed(tmp_path, capfd, monkeypatch, command):
    """``methods run`` and ``bench run`` check every frame file of the aligned dataset first."""
    from methods.raw import Raw
    from tests.bench.helpers import make_dataset

    data = make_dataset(tmp_path / "A", frames=3)
    frame = data / "hq_depth" / "000002.png"          # the last frame's reference
    frame.unlink()

    def processed(*args, **kwargs):
        raise AssertionError("a frame was processed before the frame files were checked")

    monkeypatch.setattr(Raw, "_denoise", processed)
    before = tree_digest(data)
    argv = (["methods", "run", "raw", "--data", data, "--out", tmp_path / "D", "--no-progress"] if command == "methods"
            else ["bench", "run", "--data", data, "--methods", "raw", "--out", tmp_path / "R", "--jobs", "1"])
    r = run_inproc(capfd, *argv)
    assert_one_line_error(r, str(frame), "missing")
    assert tree_digest(data) == before and sorted(os.listdir(tmp_path)) == ["A"]
