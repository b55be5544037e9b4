"""``depthbench bench report`` refuses a results folder it cannot trust: a table whose bytes changed
after its run (checked against the sha256 in results.json), a results.json that is not JSON or of
another schema version. One line, exit 2, nothing in the folder changed."""
from __future__ import annotations

import json

import pytest

from bench import results as R
from tests.capture.inproc_cli import run_inproc
from tests.capture.sessionkit import tree_digest
from tests.conftest import assert_one_line_error


@pytest.fixture(scope="module")
def results_dir(datasets, tmp_path_factory):
    from bench.runner import run_benchmark
    from tests.bench.conftest import SMALL_CONFIG

    root, a, _ = datasets
    out = tmp_path_factory.mktemp("res") / "R"
    run_benchmark([a], "raw", out, config=SMALL_CONFIG, jobs=1, progress=False, report=False)
    return out


@pytest.fixture
def copy(results_dir, tmp_path):
    import shutil

    dst = tmp_path / "R"
    shutil.copytree(results_dir, dst)
    return dst


def _flip_middle(path, n=64):
    data = bytearray(path.read_bytes())
    mid = len(data) // 2
    data[mid:mid + n] = bytes(b ^ 0x5A for b in data[mid:mid + n])
    path.write_bytes(bytes(data))


def test_intact_folder_loads(copy):
    # (the report itself is tested in test_report.py; it starts with this call)
    assert len(R.load_results(copy)) == json.loads((copy / R.MANIFEST).read_text())["table"]["rows"] > 0


def test_flipped_table_bytes_are_refused(copy, capfd):
    _flip_middle(copy / R.TABLE)
    before = tree_digest(copy)
    r = run_inproc(capfd, "bench", "report", copy, "--bootstrap", "20")
    assert_one_line_error(r, str(copy / R.TABLE), "differs from", "results.json")
    assert tree_digest(copy) == before and not (copy / "leaderboard.md").exists()


@pytest.mark.parametrize("manifest, problem", [
    ("{ not json", "not valid JSON"),
    ("schema99", "schema version 99"),
    ("", "not valid JSON"),
], ids=["not-json", "other-schema-version", "empty"])
def test_bad_manifest_is_refused(copy, capfd, manifest, problem):
    path = copy / R.MANIFEST
    if manifest == "schema99":
        meta = json.loads(path.read_text())
        meta["schema_version"] = 99
        manifest = json.dumps(meta)
    path.write_text(manifest)
    before = tree_digest(copy)
    r = run_inproc(capfd, "bench", "report", copy, "--bootstrap", "20")
    assert_one_line_error(r, str(path), problem)
    assert tree_digest(copy) == before


def test_table_path_beside_its_manifest_is_checked_too(copy):
    _flip_middle(copy / R.TABLE)
    with pytest.raises(R.ResultsFormatError, match="differs from"):
        R.load_results(copy / R.TABLE)
