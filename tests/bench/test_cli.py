"""``depthbench bench``: the real DDRNet pair end to end, and one-line errors for bad input."""
from __future__ import annotations

import json

import pytest

from bench import results as R
from tests.conftest import CliResult, assert_one_line_error


@pytest.fixture
def main(capsys):
    """``depthbench ARGS...`` in this process (fast); the subprocess runner is used where startup matters."""
    from depthbench.cli import main as depthbench_main

    def run(*args) -> CliResult:
        capsys.readouterr()
        try:
            code = depthbench_main([str(a) for a in args])
        except SystemExit as exc:       # argparse usage errors
            code = exc.code
        out = capsys.readouterr()
        return CliResult(code, out.out, out.err)

    return run


@pytest.mark.real
def test_bench_run_on_the_imported_ddrnet_pair(real_data, tmp_path, cli):
    src = real_data / "ddrnet_person"
    if not src.is_dir():
        pytest.skip(f"{src} is absent")
    r = cli("bench", "import-ddrnet", src, "--out", tmp_path / "aligned")
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in (tmp_path / "aligned").iterdir()) == ["group1", "group2"]
    from align.dataset import AlignedDataset
    ds = AlignedDataset(tmp_path / "aligned" / "group1")
    assert len(ds) == 20 and ds.depth_unit_m == 1e-3 and ds.lq_intrinsics.fx == 536.628
    fr = ds.frame(9)                                         # frame_000010: has colour
    assert fr.roi is not None and fr.lq_color is not None and fr.truth is None
    assert 1.2 < float(fr.reference[fr.roi].min()) and float(fr.lq_depth[fr.roi & (fr.lq_depth > 0)].max()) <= 2.0

    # the run: group2 (2 frames) keeps the test short; group1 is the same format
    data = tmp_path / "aligned" / "group2"
    r = cli("bench", "run", "--data", data, "--methods", "raw,bf", "--out", tmp_path / "res", "--jobs", "2")
    assert r.returncode == 0, r.stderr
    assert "4 results computed, 0 reused" in r.stdout
    t = R.load_results(tmp_path / "res")
    assert set(t["method"]) == {"raw", "bilateral"} and set(t["dataset"]) == {"ddrnet_person/group2"}
    assert set(t["reference"]) == {"hq", "hq_interior"}      # real data: no truth
    hq = t[(t["reference"] == "hq") & t["bin_lo_m"].isna()].pivot_table(index="metric", columns="method",
                                                                         values="value", aggfunc="mean")
    assert 0 < hq.loc["rmse_mm", "raw"] < 50 and hq.loc["fill_rate", "raw"] > 0.9
    assert hq.loc["mae_mm", "bilateral"] < hq.loc["mae_mm", "raw"]          # the filter helps on real data
    assert hq.loc["n_reference", "raw"] > 20000                              # the person, inside the mask
    assert 0 < hq.loc["plane_fit_rmse_mm", "raw"] < hq.loc["rmse_mm", "raw"]
    assert (tmp_path / "res" / "leaderboard.html").exists()
    again = cli("bench", "run", "--data", data, "--methods", "raw,bf", "--out", tmp_path / "res")
    assert again.returncode == 0 and "0 results computed, 4 reused" in again.stdout


def test_bad_input_is_one_line(datasets, empty_reference_dataset, tmp_path, main, cli):
    root, a, b = datasets
    cli = main      # in-process: the same parser and error handling, without interpreter start-up
    r = cli("bench", "run", "--data", a, "--methods", "raw,nosuch", "--out", tmp_path / "r")
    assert_one_line_error(r, "--methods", "unknown method 'nosuch'")
    r = cli("bench", "run", "--data", tmp_path / "missing", "--out", tmp_path / "r")
    assert_one_line_error(r, "missing", "no such aligned dataset")
    r = cli("bench", "run", "--data", empty_reference_dataset, "--methods", "raw", "--out", tmp_path / "r")
    assert_one_line_error(r, str(empty_reference_dataset), "no valid pixel")
    assert not (tmp_path / "r").exists()
    r = cli("bench", "run", "--data", a, "--methods", "raw", "--out", tmp_path / "r", "--radius-mm", "-1")
    assert_one_line_error(r, "--radius-mm")
    r = cli("bench", "run", "--data", a, "--methods", "raw", "--out", tmp_path / "r", "--scheduler", "nonsense")
    assert_one_line_error(r, "--scheduler nonsense")
    assert not (tmp_path / "r").exists()
    r = cli("bench", "report", tmp_path / "nothing")
    assert_one_line_error(r, "nothing", "no such results folder")
    r = cli("bench", "import-ddrnet", tmp_path / "nowhere", "--out", tmp_path / "x")
    assert_one_line_error(r, "nowhere", "no such folder")


def test_bad_input_through_the_real_command(datasets, tmp_path, cli):
    root, a, b = datasets
    r = cli("bench", "run", "--data", a, "--methods", "raw,nosuch", "--out", tmp_path / "r")
    assert_one_line_error(r, "--methods", "unknown method 'nosuch'")


def test_other_schema_version_via_cli(datasets, tmp_path, main):
    root, a, b = datasets
    cli = main
    out = tmp_path / "r"
    assert cli("bench", "run", "--data", a, "--methods", "raw", "--out", out, "--radius-mm", "40",
               "--no-report").returncode == 0
    meta = json.loads((out / R.MANIFEST).read_text())
    meta["schema_version"] = 99
    (out / R.MANIFEST).write_text(json.dumps(meta))
    r = cli("bench", "run", "--data", a, "--methods", "raw", "--out", out, "--radius-mm", "40")
    assert_one_line_error(r, "results.json", "schema version 99", f"reads version {R.SCHEMA_VERSION}")
    import pyarrow.parquet as pq
    t = pq.read_table(out / R.TABLE)
    pq.write_table(t.replace_schema_metadata({b"depthbench.format": b"depthbench.results",
                                              b"depthbench.schema_version": b"99"}), out / R.TABLE)
    r = cli("bench", "report", out)
    assert_one_line_error(r, "results.parquet", "schema version 99")
    r = cli("bench", "run", "--data", a, "--methods", "raw", "--out", out, "--radius-mm", "40", "--force",
            "--no-report")
    assert r.returncode == 0, r.stderr


def test_help_explains_the_results_folder(cli):
    r = cli("bench", "run", "--help")
    assert r.returncode == 0 and "continued" in r.stdout and "--scheduler" in r.stdout and "--workers" in r.stdout
