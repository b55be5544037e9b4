"""The Denoiser seams for learned methods: weights in the key, sequence scheduling, batches, the frame rule."""
from __future__ import annotations

import ast
import pickle
from pathlib import Path

import numpy as np
import pytest

from align.dataset import AlignedDataset, AlignedDatasetWriter
from methods.base import FrameInput
from methods.errors import FrameRejectedError, MethodError
from methods.output import DenoisedOutput
from methods.registry import available, register, unregister
from methods.run import denoise_dataset, plan_chunks
from tests.bench.helpers import K_SMALL, scene_depth
from tests.conftest import CliResult, assert_one_line_error
from tests.methods.seq_helpers import (BatchedScale, ChunkedTemporalMean, RejectFrame, TemporalMean,
                                       temporal_mean_reference, write_weights)

METHODS = Path(__file__).resolve().parents[2] / "methods"


def make_seq_dataset(root: Path, *, frames: int = 5, empty: tuple[int, ...] = (3,), seed: int = 3) -> Path:
    """A tiny aligned sequence (80x60): a surface moving away 5 cm per frame, noisy LQ with holes;
    the frames in ``empty`` have no valid LQ depth."""
    rng = np.random.default_rng(seed)
    meta = {"name": root.name, "lq_intrinsics": K_SMALL.to_dict(), "time_shift_us": 0, "T_lq_hq": np.eye(4).tolist()}
    with AlignedDatasetWriter(root, meta) as w:
        for i in range(frames):
            t = scene_depth(K_SMALL, base=1.2 + 0.05 * i)
            lq = (t + rng.normal(0, 0.004, t.shape)).astype(np.float32)
            lq[rng.random(t.shape) < 0.05] = np.nan
            if i in empty:
                lq[:] = np.nan
            ref = (t + rng.normal(0, 0.001, t.shape)).astype(np.float32)
            col = (rng.random(t.shape + (3,)) * 255).astype(np.uint8)
            w.add_frame(lq, ref, lq_color=col, truth=t, lq_frame=i, hq_frame=i, lq_timestamp_us=i * 33_333)
    return root


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """Five frames; frame 3 has no valid LQ depth."""
    return AlignedDataset(make_seq_dataset(tmp_path_factory.mktemp("seams") / "A"))


def _lq(ds):
    return [ds.lq_depth(i) for i in range(len(ds))]


# ----------------------------------------------------------------------------------- weights
def test_weights_hash_is_the_key_not_the_path(tmp_path):
    a = write_weights(tmp_path / "a.npz", alpha=0.5)
    b = write_weights(tmp_path / "b.npz", alpha=0.5)          # same bytes, other path
    c = write_weights(tmp_path / "c.npz", alpha=0.6)
    ka, kb, kc = (TemporalMean(weights=str(p)).key for p in (a, b, c))
    assert ka == kb and ka != kc
    assert "a.npz" not in ka and "sha256:" in ka
    desc = TemporalMean(weights=str(c)).describe()
    assert desc["weights"]["file"] == str(c.resolve()) and len(desc["weights"]["sha256"]) == 64


def test_weights_errors_are_one_line_method_errors(tmp_path):
    with pytest.raises(MethodError, match="needs a weights file"):
        TemporalMean()
    with pytest.raises(MethodError, match="no such weights file"):
        TemporalMean(weights=str(tmp_path / "missing.npz"))
    with pytest.raises(MethodError, match="must be a .safetensors or .npz"):
        TemporalMean(weights=str(tmp_path / "w.pt"))
    pickled = tmp_path / "p.npz"
    np.savez(pickled, alpha=np.array([{"evil": 1}], dtype=object))
    with pytest.raises(MethodError, match="not a readable weights file"):
        TemporalMean(weights=str(pickled)).load_weights()
    w = write_weights(tmp_path / "w.npz", alpha=0.5)
    m = TemporalMean(weights=str(w))
    write_weights(w, alpha=0.7)                                # changed after the key was taken
    with pytest.raises(MethodError, match="weights changed"):
        m.weights_bytes()


def test_safetensors_and_npz_weights_give_the_same_model(tmp_path, dataset):
    npz = TemporalMean(weights=str(write_weights(tmp_path / "w.npz", alpha=0.3, offset_m=0.01)))
    st = TemporalMean(weights=str(write_weights(tmp_path / "w.safetensors", alpha=0.3, offset_m=0.01)))
    frames = [FrameInput(i, d) for i, d in enumerate(_lq(dataset)[:3])]
    for x, y in zip(npz.denoise_sequence(frames), st.denoise_sequence(frames)):
        np.testing.assert_array_equal(x, y)


def test_runtime_state_is_not_pickled(tmp_path):
    m = TemporalMean(weights=str(write_weights(tmp_path / "w.npz", alpha=0.5)))
    m.denoise(np.ones((4, 5), np.float32))
    assert m.runtime["_prepared"]
    copy = pickle.loads(pickle.dumps(m))
    assert copy.runtime == {} and copy.key == m.key


# ----------------------------------------------------------------------------------- scheduling
def test_plan_chunks_covers_every_frame_once_in_order(tmp_path):
    w = str(write_weights(tmp_path / "w.npz", alpha=0.5))
    whole = plan_chunks(TemporalMean(weights=w), 5)
    assert [c.frames for c in whole] == [(0, 1, 2, 3, 4)] and whole[0].warmup == ()
    chunked = plan_chunks(ChunkedTemporalMean(weights=w), 5)
    assert [c.frames for c in chunked] == [(0, 1), (2, 3), (4,)]
    assert [c.warmup for c in chunked] == [(), (1,), (3,)]
    assert [c.frames for c in plan_chunks(BatchedScale(), 5)] == [(0, 1), (2, 3), (4,)]
    assert [c.frames for c in plan_chunks(RejectFrame(), 2)] == [(0,), (1,)]


@pytest.mark.parametrize("cls, chunk, warmup", [(TemporalMean, None, 0), (ChunkedTemporalMean, 2, 1)])
def test_sequence_method_over_a_dataset_matches_a_direct_loop(tmp_path, dataset, cls, chunk, warmup):
    """Frame order, chunks with warm-up, and the empty frame 3 (not fed; state carries over)."""
    m = cls(weights=str(write_weights(tmp_path / "w.npz", alpha=0.4, offset_m=0.002)))
    res = denoise_dataset(m, dataset, tmp_path / "out", progress=False)
    assert res.frames == 5 and res.empty == 1
    got = DenoisedOutput(tmp_path / "out")
    want = temporal_mean_reference(_lq(dataset), alpha=0.4, offset_m=0.002, chunk=chunk, warmup=warmup)
    for i in range(5):
        # the written PNG quantises to the dataset's depth unit (0.1 mm)
        np.testing.assert_allclose(got.depth(i), want[i], atol=0.6e-4, equal_nan=True)
    assert np.isnan(got.depth(3)).all()


def test_batched_method_gets_batches_and_matches_per_frame(tmp_path, dataset):
    BatchedScale.calls.clear()
    denoise_dataset(BatchedScale(factor=1.02), dataset, tmp_path / "out", progress=False)
    assert BatchedScale.calls and max(BatchedScale.calls) == 2   # frame 3 is empty: never in a batch
    assert sum(BatchedScale.calls) == 4
    got = DenoisedOutput(tmp_path / "out")
    for i, d in enumerate(_lq(dataset)):
        np.testing.assert_allclose(got.depth(i), d * 1.02, atol=0.6e-4, equal_nan=True)


# ----------------------------------------------------------------------------------- the frame rule
def test_rejected_frame_stops_the_run_and_writes_nothing(tmp_path, dataset):
    with pytest.raises(FrameRejectedError) as err:
        denoise_dataset(RejectFrame(), dataset, tmp_path / "out", progress=False)
    msg = str(err.value)
    assert "frame 2" in msg and str(dataset.root) in msg and "test_reject_frame@1" in msg and "\n" not in msg
    assert not (tmp_path / "out").exists() and list(tmp_path.iterdir()) == []


@pytest.fixture
def registered():
    for cls in (RejectFrame, TemporalMean):
        register(cls)
    yield
    for cls in (RejectFrame, TemporalMean):
        unregister(cls.name)


def _main(capsys, *args) -> CliResult:
    from depthbench.cli import main

    rc = main([str(a) for a in args])
    out = capsys.readouterr()
    return CliResult(rc, out.out, out.err)


def test_methods_run_rejected_frame_is_one_line_exit_2(tmp_path, dataset, registered, capsys):
    r = _main(capsys, "methods", "run", "test_reject_frame", "--data", dataset.root, "--out", tmp_path / "o",
              "--no-progress")
    assert_one_line_error(r, "frame 2", "test_reject_frame@1", "refused it")
    assert not (tmp_path / "o").exists()


def test_methods_run_takes_weights_as_a_param(tmp_path, dataset, registered, capsys):
    w = write_weights(tmp_path / "w.npz", alpha=0.5)
    r = _main(capsys, "methods", "run", "test_temporal_mean", "--data", dataset.root, "--out", tmp_path / "o",
              "--param", f"weights={w}", "--no-progress")
    assert r.returncode == 0, r.stderr
    assert "sha256:" in r.stdout and "1 without valid depth" in r.stdout
    r = _main(capsys, "methods", "run", "test_temporal_mean", "--data", dataset.root, "--out", tmp_path / "o2",
              "--no-progress")
    assert_one_line_error(r, "needs a weights file")


# ----------------------------------------------------------------------------------- registry
def _method_imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("methods"):
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names |= {a.name for a in node.names if a.name.startswith("methods")}
    return names


def test_method_modules_have_no_import_cycle():
    """The import graph of methods/*.py (every import, function-level ones too) has no cycle."""
    graph = {f"methods.{p.stem}": _method_imports(p) for p in METHODS.glob("*.py") if p.stem != "__init__"}
    assert "methods.registry" not in graph["methods.base"]
    state: dict[str, int] = {}

    def visit(node, path):
        if state.get(node) == 1:
            raise AssertionError(f"import cycle: {' -> '.join(path + [node])}")
        if state.get(node) == 2 or node not in graph:
            return
        state[node] = 1
        for nxt in graph[node]:
            visit(nxt, path + [node])
        state[node] = 2

    for node in graph:
        visit(node, [])


def test_methods_list_shows_aliases(capsys):
    r = _main(capsys, "methods", "list")
    assert "bilateral  (version 1, alias bf)" in r.stdout
    assert "joint_bilateral  (version 1, alias jbf" in r.stdout
    assert "rolling_guidance  (version 1, alias rgf" in r.stdout
    listing = _main(capsys, "methods", "list", "--json").stdout
    import json

    entries = {e["name"]: e for e in json.loads(listing)}
    assert entries["bilateral"]["aliases"] == ["bf"] and set(entries) == set(available())
