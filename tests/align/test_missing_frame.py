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
