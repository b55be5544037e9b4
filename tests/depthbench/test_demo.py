"""The demo on a tiny configuration: every stage runs through the library and the outputs agree with it."""
from __future__ import annotations

import pandas as pd
import pytest

from bench import results as R
from depthbench.demo import DemoConfig, run_demo
from tests.conftest import assert_one_line_error

#: Under a second of scene time at half resolution, six probe frames, two methods, no reports, no training.
TINY = DemoConfig(seconds=0.8, seed=3, scale=0.5, methods="raw,gaussian", jobs=1, progress=False, probes=6,
                  reports=False, learned=False)


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "out"
    return run_demo(out, config=TINY)


def test_demo_runs_every_stage_into_its_folder(demo):
    assert [s.status for s in demo.steps] == ["done"] * 3
    assert [s.output.name for s in demo.steps] == ["session", "aligned", "results"]
    assert (demo.out / "session" / "session.json").is_file()
    assert (demo.out / "aligned" / "aligned.json").is_file()
    table = R.load_results(demo.out / "results")
    assert set(table["method"]) == {"raw", "gaussian", "hq_sensor"}
    assert demo.steps[0].command.startswith("depthbench capture simulate --rig lq-hq")


def test_demo_results_equal_the_benchmark_library_on_its_aligned_data(demo, tmp_path):
    """The demo's bench step is run_benchmark with the command it prints (the plane fit's radius
    scaled to the image: 5 mm / 0.5): the same table."""
    from bench.metrics import MetricConfig
    from bench.runner import run_benchmark

    assert "--radius-mm 10 " in demo.steps[-1].command
    again = run_benchmark([demo.out / "aligned"], "raw,gaussian", tmp_path / "r", jobs=1, report=False,
                          config=MetricConfig(radius_m=0.010))
    pd.testing.assert_frame_equal(R.load_results(demo.out / "results"), again.table, check_exact=True)
    assert (R.load_results(tmp_path / "r")["metric"] == "plane_fit_rmse_mm").any()


def test_demo_refuses_an_existing_folder_and_bad_seconds(tmp_path, capsys):
    from depthbench.cli import main

    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "keep.txt").write_text("mine")
    rc = main(["demo", "--out", str(tmp_path / "x"), "--seconds", "1"])
    err = capsys.readouterr().err
    assert rc == 2 and "exists" in err and (tmp_path / "x" / "keep.txt").read_text() == "mine"
    rc = main(["demo", "--out", str(tmp_path / "y"), "--seconds", "0"])
    err = capsys.readouterr().err
    from tests.conftest import CliResult

    assert_one_line_error(CliResult(rc, "", err), "--seconds must be positive")
    assert not (tmp_path / "y").exists()


def test_demo_refuses_a_bad_scale(tmp_path, capsys):
    from depthbench.cli import main
    from tests.conftest import CliResult

    rc = main(["demo", "--out", str(tmp_path / "z"), "--scale", "1.5"])
    assert_one_line_error(CliResult(rc, "", capsys.readouterr().err), "--scale must be in (0, 1]")
    assert not (tmp_path / "z").exists()


def test_parallel_steps_start_after_the_steps_they_need_and_a_failure_stops_the_rest(tmp_path):
    """The demo's scheduler (two worker processes): a step runs only once what it needs is done, whatever
    the plan order; a failing step raises its error and what depends on it never runs."""
    import shutil
    import time
    from functools import partial
    from pathlib import Path

    from depthbench.demo import DemoStep, _run_parallel

    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    steps = [DemoStep(name="copy", command="", call=partial(shutil.copyfile, a, b), output=b, needs=("slow write",)),
             DemoStep(name="slow write", command="", call=partial(_sleep_then_write, a, "x"), output=a),
             DemoStep(name="sleep", command="", call=partial(time.sleep, 0.1), output=tmp_path)]
    _run_parallel(steps, 2)
    assert b.read_text() == "x" and [s.status for s in steps] == ["done"] * 3
    bad = [DemoStep(name="fails", command="", call=partial(shutil.copyfile, tmp_path / "missing", c), output=c),
           DemoStep(name="after", command="", call=partial(Path.write_text, c, "no"), output=c, needs=("fails",))]
    with pytest.raises(FileNotFoundError):
        _run_parallel(bad, 2)
    assert [s.status for s in bad] == ["failed", "pending"] and not c.exists()


def _sleep_then_write(path, text):
    import time

    time.sleep(0.5)
    path.write_text(text)


def test_learned_demo_benchmarks_each_training_as_it_ends_in_one_chain_into_one_folder(tmp_path):
    """With the trainings, the benchmark is one run per group into the same results folder: the filters
    after the alignment, each training's methods after it, chained (never two writers at once); only
    the first may replace the folder, the last (after every training) scores every method with a report."""
    from depthbench.demo import plan

    steps = plan(tmp_path / "d", DemoConfig(seconds=1, probes=6), force=True)
    names = [s.name for s in steps]
    benches = [s for s in steps if s.name.startswith("benchmark")]
    trainings = [s.name for s in steps if s.name.startswith("train ")]
    assert len(trainings) == 3 and [b.output for b in benches] == [tmp_path / "d" / "results"] * 4
    assert benches[0].needs == ("align HQ onto LQ",) and "--force" in benches[0].command
    assert benches[0].call.keywords["force"] and not any(b.call.keywords["force"] for b in benches[1:])
    for prev, b in zip(benches, benches[1:]):
        assert prev.name in b.needs and names.index(prev.name) < names.index(b.name)
        assert "--force" not in b.command
    assert "ssdd" not in " ".join(b.call.args[1] for b in benches[:-1])          # SSDD, the longest, last
    last = benches[-1]
    assert last.name == "benchmark every method" and set(trainings) <= set(last.needs)
    assert last.call.args[1] == "all" and last.call.keywords["report"]
    assert set(last.call.keywords["params"]) == {"ddrnet", "ddrnet_refine", "ddd", "ssdd_unet", "ssdd_lstm"}
    for b in benches[1:-1]:
        assert b.call.args[1].split(",") == list(b.call.keywords["params"])
        assert any(t in b.needs for t in trainings)


def test_the_demos_own_four_view_corpus_aligns(tmp_path):
    """The demo's four-view step exactly as `make demo` runs it (its seed, scale, probes): every view gets a
    calibrated dataset. In session 9 two changes elsewhere (the simulator's shift draw, the photometric
    keypoint refinement) made it stop on "only 2 3D-2D feature pairs" while every other test passed."""
    import json

    from depthbench.demo import plan

    steps = {s.name: s for s in plan(tmp_path / "d", DemoConfig(progress=False), force=True)}
    step = steps["simulate + align four views (DDD)"]
    step.call()
    manifest = json.loads((step.output / "training.json").read_text())
    assert len(manifest["datasets"]) == 4, manifest
