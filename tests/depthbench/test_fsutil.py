"""Crash-safe output helpers."""
import os

import pytest

from depthbench.errors import OutputExistsError, UnsafePathError
from depthbench.fsutil import atomic_output, atomic_write_text, check_output_free, safe_join, staged_directory


def test_atomic_write_leaves_no_temp_and_replaces(tmp_path):
    p = tmp_path / "a.txt"
    atomic_write_text(p, "one")
    atomic_write_text(p, "two")
    assert p.read_text() == "two"
    assert os.listdir(tmp_path) == ["a.txt"]


def test_atomic_output_keeps_old_file_on_error(tmp_path):
    p = tmp_path / "t.parquet"
    p.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_output(p) as tmp:
            tmp.write_text("half")
            raise RuntimeError("boom")
    assert p.read_text() == "old"
    assert os.listdir(tmp_path) == ["t.parquet"]


def test_staged_directory_publishes_only_on_success(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(RuntimeError):
        with staged_directory(out) as d:
            (d / "x").write_text("x")
            raise RuntimeError("boom")
    assert not out.exists() and os.listdir(tmp_path) == []
    with staged_directory(out) as d:
        (d / "x").write_text("x")
    assert (out / "x").read_text() == "x"


def test_existing_output_needs_force(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep").write_text("precious")
    with pytest.raises(OutputExistsError, match="output exists$"):
        with staged_directory(out):
            pass
    assert (out / "keep").read_text() == "precious"
    with staged_directory(out, force=True) as d:
        (d / "new").write_text("n")
    assert sorted(os.listdir(out)) == ["new"]
    check_output_free(tmp_path / "empty-does-not-exist", force=False)


@pytest.mark.parametrize("rel", ["../x.png", "/etc/passwd", "a/../../b", ""])
def test_safe_join_refuses_escapes(tmp_path, rel):
    with pytest.raises(UnsafePathError):
        safe_join(tmp_path, rel, source="frames.csv")


def test_safe_join_accepts_inside(tmp_path):
    assert safe_join(tmp_path, "lq/depth/1.png") == (tmp_path / "lq/depth/1.png").resolve()


def test_published_outputs_follow_the_umask_not_tempfile_privacy(tmp_path):
    old = os.umask(0o022)
    try:
        atomic_write_text(tmp_path / "f.txt", "x")
        with atomic_output(tmp_path / "g.bin") as tmp:
            tmp.write_bytes(b"x")
        with staged_directory(tmp_path / "d") as d:
            (d / "x").write_text("x")
    finally:
        os.umask(old)
    assert (tmp_path / "f.txt").stat().st_mode & 0o777 == 0o644
    assert (tmp_path / "g.bin").stat().st_mode & 0o777 == 0o644
    assert (tmp_path / "d").stat().st_mode & 0o777 == 0o755


def test_read_json_names_the_file_and_the_problem(tmp_path):
    from depthbench.errors import DepthbenchError
    from depthbench.fsutil import read_json

    class Oops(DepthbenchError):
        pass

    with pytest.raises(Oops, match=r"m\.json: missing \(not here\)$"):
        read_json(tmp_path / "m.json", error=Oops, missing=" (not here)")
    (tmp_path / "m.json").write_text("{bad")
    with pytest.raises(Oops, match=r"m\.json: not valid JSON \(.*\); no luck$"):
        read_json(tmp_path / "m.json", error=Oops, missing="", invalid_note="; no luck")
    (tmp_path / "m.json").write_text('{"a": 1}')
    assert read_json(tmp_path / "m.json", error=Oops, missing="") == {"a": 1}
