"""The runner: executors agree exactly, the cache is used and invalidated correctly, bad input is refused."""
from __future__ import annotations

import hashlib
import json

import numpy as np
import pandas as pd
import pytest

from bench import results as R
from bench.runner import EmptyReferenceError, run_benchmark
from depthbench.errors import OutputExistsError
from methods.errors import UnknownMethodError
from tests.bench.conftest import SMALL_CONFIG
from tests.bench.helpers import Shift, ShiftV2, Smooth


def sha(p):
    return hashlib.sha256(p.read_bytes()).hexdigest()


def run(datasets, methods, out, **kw):
    kw.setdefault("config", SMALL_CONFIG)
    kw.setdefault("report", False)
    return run_benchmark(datasets, methods, out, **kw)


def test_serial_process_and_dask_runs_write_identical_tables(datasets, tmp_path):
    root, a, b = datasets
    methods = ["raw", Shift(), Smooth()]
    serial = run([a, b], methods, tmp_path / "serial", jobs=1)
    procs = run([a, b], methods, tmp_path / "procs", jobs=2)
    dask = run([a, b], methods, tmp_path / "dask", workers=2)
    assert len(serial.table) > 0 and serial.computed == 3 * 6 + 3   # 3 methods x 6 frames + HQ sensor x 3
    pd.testing.assert_frame_equal(serial.table, procs.table, check_exact=True)
    pd.testing.assert_frame_equal(serial.table, dask.table, check_exact=True)
    assert sha(serial.table_path) == sha(procs.table_path) == sha(dask.table_path)
    assert R.load_results(tmp_path / "dask").equals(serial.table)


def test_table_has_one_row_per_method_dataset_frame_reference_metric(datasets, tmp_path):
    root, a, b = datasets
    res = run([root], ["raw", Smooth()], tmp_path / "r", jobs=1)     # a folder of datasets stands for all
    t = res.table
    assert tuple(t.columns) == R.COLUMNS
    assert set(t["dataset"]) == {"A", "B"} and set(t["sequence"]) == {"seq-a", "seq-b"}
    assert set(t["reference"]) == {"hq", "truth", "truth_noref", "hq_interior", "truth_interior"}
    assert set(t.loc[t["dataset"] == "B", "reference"]) == {"hq", "hq_interior"}     # no truth in B
    assert set(t.loc[t["method"] == "hq_sensor", "reference"]) == {"truth", "truth_interior"}
    frame_rows = t[t["bin_lo_m"].isna()]
    assert not frame_rows.duplicated(["method_key", "dataset", "frame", "reference", "metric"]).any()
    assert (t["schema_version"] == R.SCHEMA_VERSION).all()
    # rows agree with the metric functions on the frame itself
    from align.dataset import AlignedDataset
    from bench.metrics import frame_metrics, moving_mask
    ds = AlignedDataset(a)
    fr = ds.frame(1)
    moving = moving_mask(fr.truth, ds.truth(0), threshold_m=SMALL_CONFIG.moving_threshold_m)   # A has truth
    want, _ = frame_metrics(fr.lq_depth, fr.reference, ds.lq_intrinsics, roi=fr.roi, config=SMALL_CONFIG,
                            moving=moving)
    got = frame_rows[(frame_rows["method"] == "raw") & (frame_rows["dataset"] == "A") & (frame_rows["frame"] == 1)
                     & (frame_rows["reference"] == "hq")].set_index("metric")["value"]
    for k, v in want.items():
        assert got[k] == pytest.approx(v, rel=1e-12, nan_ok=True), k
    manifest = json.loads((tmp_path / "r" / R.MANIFEST).read_text())
    assert manifest["table"]["sha256"] == sha(res.table_path)
    assert manifest["metrics"]["radius_m"] == SMALL_CONFIG.radius_m


def test_second_run_recomputes_nothing(datasets, tmp_path):
    root, a, b = datasets
    out = tmp_path / "r"
    first = run([a, b], ["raw", Smooth()], out, jobs=1)
    parts = sorted((out / R.CACHE).rglob("*.parquet"))
    stamps = [p.stat().st_mtime_ns for p in parts]
    second = run([a, b], ["raw", Smooth()], out, jobs=1)
    assert second.computed == 0 and second.reused == first.computed
    assert [p.stat().st_mtime_ns for p in parts] == stamps
    pd.testing.assert_frame_equal(first.table, second.table, check_exact=True)


def test_changed_method_version_recomputes_only_that_method(datasets, tmp_path):
    root, a, b = datasets
    out = tmp_path / "r"
    run([a, b], ["raw", Shift(), Smooth()], out, jobs=1)
    again = run([a, b], ["raw", ShiftV2(), Smooth()], out, jobs=1)
    assert again.computed == 6                     # test_shift@2 on 3 + 3 frames
    assert again.reused == 2 * 6 + 3
    keys = set(again.table["method_key"])
    assert ShiftV2().key in keys and Shift().key not in keys
    assert again.superseded == sorted(f"{Shift().key} on {n}" for n in ("A", "B"))
    runs = json.loads((out / R.MANIFEST).read_text())["runs"]
    assert [r["computed"] for r in runs] == [21, 6]


def test_continuing_a_folder_keeps_methods_this_run_does_not_name(datasets, tmp_path):
    root, a, b = datasets
    out = tmp_path / "r"
    run([a], ["raw"], out, jobs=1)
    res = run([a, b], [Smooth()], out, jobs=1)
    t = res.table
    assert set(zip(t["method"], t["dataset"])) >= {("raw", "A"), ("test_smooth", "A"), ("test_smooth", "B")}
    assert ("raw", "B") not in set(zip(t["method"], t["dataset"]))
    assert res.superseded == []


def test_unknown_method_and_bad_executor_arguments(datasets, tmp_path):
    root, a, b = datasets
    with pytest.raises(UnknownMethodError, match="--methods: unknown method 'nope'"):
        run([a], "raw,nope", tmp_path / "r")
    with pytest.raises(Exception, match="--workers.*--scheduler|not both"):
        run([a], "raw", tmp_path / "r", workers=2, scheduler="tcp://127.0.0.1:1")
    assert not (tmp_path / "r").exists()


def test_empty_reference_is_an_error_and_leaves_nothing(empty_reference_dataset, tmp_path):
    with pytest.raises(EmptyReferenceError, match="no valid pixel inside the ROI in any of its 3 frames"):
        run([empty_reference_dataset], ["raw"], tmp_path / "r", jobs=1)
    assert not (tmp_path / "r").exists()
    assert list(tmp_path.iterdir()) == []


def test_failed_run_into_a_new_folder_leaves_nothing(datasets, tmp_path):
    root, a, b = datasets

    class Boom(Shift):
        name = "boom"

        def _denoise(self, depth, color, camera):
            raise RuntimeError("kaboom")

    with pytest.raises(RuntimeError, match="kaboom"):
        run([a], ["raw", Boom()], tmp_path / "r", jobs=1)
    assert list(tmp_path.iterdir()) == []


def test_other_schema_version_is_refused(datasets, tmp_path):
    root, a, b = datasets
    out = tmp_path / "r"
    res = run([a], ["raw"], out, jobs=1)
    meta = json.loads((out / R.MANIFEST).read_text())
    meta["schema_version"] = 99
    (out / R.MANIFEST).write_text(json.dumps(meta))
    with pytest.raises(R.SchemaVersionError, match="schema version 99"):
        run([a], ["raw"], out, jobs=1)
    # a table written by another schema version (file metadata and column) is refused by the reader
    old = res.table.copy()
    old["schema_version"] = 0
    import pyarrow as pa
    import pyarrow.parquet as pq
    table = pa.Table.from_pandas(old, preserve_index=False).replace_schema_metadata(
        {b"depthbench.format": b"depthbench.results", b"depthbench.schema_version": b"0"})
    pq.write_table(table, out / R.TABLE)
    with pytest.raises(R.SchemaVersionError, match=f"results schema version 0, this depthbench reads version {R.SCHEMA_VERSION}"):
        R.load_results(out)
    # --force replaces the folder
    again = run([a], ["raw"], out, jobs=1, force=True)
    assert again.computed == 6 and R.read_manifest(out)["schema_version"] == R.SCHEMA_VERSION   # raw + HQ sensor


def test_existing_folder_that_is_not_results_needs_force(datasets, tmp_path):
    root, a, b = datasets
    out = tmp_path / "r"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with pytest.raises(OutputExistsError, match="not a depthbench results folder"):
        run([a], ["raw"], out, jobs=1)
    assert (out / "notes.txt").read_text() == "mine"
    run([a], ["raw"], out, jobs=1, force=True)
    assert not (out / "notes.txt").exists() and (out / R.TABLE).exists()


def test_other_metric_parameters_are_refused(datasets, tmp_path):
    from bench.metrics import MetricConfig
    root, a, b = datasets
    out = tmp_path / "r"
    run([a], ["raw"], out, jobs=1)
    with pytest.raises(Exception, match="metric parameters"):
        run([a], ["raw"], out, jobs=1, config=MetricConfig(radius_m=0.01))


def test_previews_hold_no_pickles(datasets, tmp_path):
    root, a, b = datasets
    out = tmp_path / "r"
    res = run([a], ["raw", Smooth()], out, jobs=1)
    files = sorted((out / R.PREVIEWS).rglob("*.npz"))
    assert len(files) == 1 + 3                      # inputs + raw, smooth, hq sensor
    for f in files:
        with np.load(f, allow_pickle=False) as z:
            assert all(z[k].dtype != object for k in z.files)
    del res
