"""Learned-method seams in the benchmark: a sequence method with a weights file on every executor,
its per-frame cache, its weights in the key, and the frame rule shared with ``methods run``."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest

from align.dataset import AlignedDataset
from bench import results as R
from bench.runner import run_benchmark
from methods.errors import FrameRejectedError
from methods.registry import register, unregister
from tests.bench.conftest import SMALL_CONFIG
from tests.bench.helpers import Smooth
from tests.conftest import CliResult, assert_one_line_error
from tests.methods.seq_helpers import ChunkedTemporalMean, RejectFrame, TemporalMean, temporal_mean_reference, \
    write_weights
from tests.methods.test_seams import make_seq_dataset


@pytest.fixture(scope="module")
def seq_data(tmp_path_factory):
    """Two 5-frame sequences (frame 3 of the first has no valid LQ depth) and a weights file."""
    root = tmp_path_factory.mktemp("seqbench")
    a = make_seq_dataset(root / "S1", empty=(3,), seed=1)
    b = make_seq_dataset(root / "S2", empty=(), seed=2)
    weights = write_weights(root / "w.npz", alpha=0.4, offset_m=0.002)
    return a, b, weights


def _run(data, methods, out, **kw):
    return run_benchmark(data, methods, out, config=SMALL_CONFIG, report=False, **kw)


def _methods(weights):
    return [Smooth(), TemporalMean(weights=str(weights)), ChunkedTemporalMean(weights=str(weights))]


def test_sequence_method_is_identical_serial_process_pool_and_dask(seq_data, tmp_path):
    a, b, weights = seq_data
    serial = _run([a, b], _methods(weights), tmp_path / "serial", jobs=1)
    procs = _run([a, b], _methods(weights), tmp_path / "procs", jobs=2)
    dask = _run([a, b], _methods(weights), tmp_path / "dask", workers=2)
    assert serial.computed == 3 * 10 + 10           # 3 methods x 2 x 5 frames + the HQ sensor
    pd.testing.assert_frame_equal(serial.table, procs.table, check_exact=True)
    pd.testing.assert_frame_equal(serial.table, dask.table, check_exact=True)
    # the scored output is the running mean in frame order, chunked as the method says
    ds = AlignedDataset(a)
    frames = [ds.lq_depth(i) for i in range(len(ds))]
    mid = json.loads((tmp_path / "serial" / R.MANIFEST).read_text())["datasets"][0]["preview_frame"]
    for cls, chunk, warm in ((TemporalMean, None, 0), (ChunkedTemporalMean, 2, 1)):
        want = temporal_mean_reference(frames, alpha=0.4, offset_m=0.002, chunk=chunk, warmup=warm)[mid]
        key = cls(weights=str(weights)).key
        with np.load(R.preview_path(tmp_path / "serial", ds.checksum, key), allow_pickle=False) as got:
            np.testing.assert_allclose(got["depth"], want, rtol=0, atol=1e-6, equal_nan=True)


def test_cache_survives_a_second_run_and_new_weights_recompute_only_their_rows(seq_data, tmp_path):
    a, b, weights = seq_data
    out = tmp_path / "r"
    first = _run([a, b], _methods(weights), out, jobs=1)
    second = _run([a, b], _methods(weights), out, jobs=1)
    assert second.computed == 0 and second.reused == first.computed
    pd.testing.assert_frame_equal(first.table, second.table, check_exact=True)

    new_weights = write_weights(tmp_path / "w2.npz", alpha=0.7, offset_m=0.002)
    moved = shutil.copy(weights, tmp_path / "moved.npz")      # same bytes elsewhere: same key, nothing to do
    third = _run([a, b], [Smooth(), TemporalMean(weights=str(new_weights)), ChunkedTemporalMean(weights=moved)],
                 out, jobs=1)
    assert third.computed == 10                     # TemporalMean on 2 x 5 frames; the others from the cache
    new_key = TemporalMean(weights=str(new_weights)).key
    assert third.superseded == sorted(f"{TemporalMean(weights=str(weights)).key} on {n}" for n in ("S1", "S2"))
    entry = {m["key"]: m for m in json.loads((out / R.MANIFEST).read_text())["methods"]}[new_key]
    assert entry["weights"]["file"] == str(new_weights.resolve()) and new_key.endswith(
        f"weights=sha256:{entry['weights']['sha256'][:16]})")
    t = third.table
    changed = t[t["method_key"] == new_key]
    assert len(changed) and not changed["value"].equals(first.table.loc[
        first.table["method_key"] == TemporalMean(weights=str(weights)).key, "value"].reset_index(drop=True))


# ----------------------------------------------------------------------------------- the frame rule
@pytest.fixture
def reject_registered():
    register(RejectFrame)
    yield
    unregister(RejectFrame.name)


def _main(capsys, *args) -> CliResult:
    from depthbench.cli import main

    rc = main([str(a) for a in args])
    out = capsys.readouterr()
    return CliResult(rc, out.out, out.err)


def test_methods_run_and_bench_run_treat_a_rejected_frame_alike(seq_data, tmp_path, reject_registered, capsys):
    """The documented rule (methods/run.py): the run stops with one line naming dataset, frame and
    method key, exit status 2, and nothing is published by either command."""
    a, b, _ = seq_data
    m = _main(capsys, "methods", "run", "test_reject_frame", "--data", a, "--out", tmp_path / "m", "--no-progress")
    r = _main(capsys, "bench", "run", "--data", a, "--methods", "raw,test_reject_frame", "--out", tmp_path / "b",
              "--jobs", "1", "--radius-mm", "40", "--no-report")
    for res in (m, r):
        assert_one_line_error(res, "frame 2", f"{RejectFrame().key} refused it", "mean depth")
    assert m.stderr.split("error: ", 1)[1] == r.stderr.split("error: ", 1)[1]
    assert not (tmp_path / "m").exists() and not (tmp_path / "b").exists()
    with pytest.raises(FrameRejectedError):
        _run([a], [RejectFrame()], tmp_path / "lib", jobs=2)
    assert not (tmp_path / "lib").exists()


def test_methods_run_and_bench_run_treat_an_empty_frame_alike(seq_data, tmp_path, capsys):
    """A frame without valid LQ depth: ``methods run`` writes it empty, ``bench run`` scores an empty prediction."""
    a, _, weights = seq_data
    from methods.output import DenoisedOutput
    from methods.run import denoise_dataset

    denoise_dataset(TemporalMean(weights=str(weights)), a, tmp_path / "m", progress=False)
    assert np.isnan(DenoisedOutput(tmp_path / "m").depth(3)).all()
    res = _run([a], [TemporalMean(weights=str(weights))], tmp_path / "b", jobs=1)
    rows = res.table[(res.table["method"] == "test_temporal_mean") & (res.table["frame"] == 3)
                     & res.table["bin_lo_m"].isna() & (res.table["reference"] == "hq")].set_index("metric")["value"]
    assert rows["n_valid"] == 0 and rows["fill_rate"] == 0 and np.isnan(rows["mae_mm"])


def test_bench_cli_takes_method_params_and_all_includes_learned_methods_with_weights(seq_data, tmp_path, capsys):
    a, _, weights = seq_data
    register(TemporalMean)
    try:
        r = _main(capsys, "bench", "run", "--data", a, "--methods", "all", "--param",
                  f"test_temporal_mean.weights={weights}", "--param", "bf.sigma_color=0.03", "--out", tmp_path / "r",
                  "--jobs", "1", "--radius-mm", "40", "--no-report")
        assert r.returncode == 0, r.stderr
        manifest = json.loads((tmp_path / "r" / R.MANIFEST).read_text())
        keys = {m["key"] for m in manifest["methods"]}
        assert TemporalMean(weights=str(weights)).key in keys
        assert any(k.startswith("bilateral@") and "sigma_color=0.03" in k for k in keys)
        r = _main(capsys, "bench", "run", "--data", a, "--methods", "all", "--out", tmp_path / "r2", "--jobs", "1",
                  "--radius-mm", "40", "--no-report")      # without weights the learned method is not in 'all'
        assert r.returncode == 0, r.stderr
        assert "test_temporal_mean" not in {m["name"] for m in json.loads((tmp_path / "r2" / R.MANIFEST).read_text())["methods"]}
        r = _main(capsys, "bench", "run", "--data", a, "--methods", "raw", "--param", "bf.sigma_color=0.03",
                  "--out", tmp_path / "r3")
        assert_one_line_error(r, "--param", "'bilateral' is not among the methods")
        r = _main(capsys, "bench", "run", "--data", a, "--methods", "raw", "--param", "nosuch", "--out", tmp_path / "r3")
        assert_one_line_error(r, "--param 'nosuch'", "METHOD.NAME=VALUE")
        assert not (tmp_path / "r3").exists()
    finally:
        unregister(TemporalMean.name)


def test_a_method_refusing_a_dataset_stops_both_runs_before_any_work(seq_data, tmp_path):
    from methods.errors import MethodError
    from methods.run import denoise_dataset
    from tests.methods.seq_helpers import RefuseDataset

    a, b, _ = seq_data
    with pytest.raises(MethodError, match="in its training split"):
        _run([b, a], ["raw", RefuseDataset()], tmp_path / "r", jobs=1)
    with pytest.raises(MethodError, match="in its training split"):
        denoise_dataset(RefuseDataset(), a, tmp_path / "m", progress=False)
    assert list(tmp_path.iterdir()) == []
    assert _run([b], [RefuseDataset()], tmp_path / "ok", jobs=1).computed == 5 + 5
