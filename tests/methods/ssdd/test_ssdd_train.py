"""SSDD trained for real (a tiny config on synthetic sequences): out-of-fold proof, inference through
the Denoiser interface, and the leaderboard's refusal to score a model on its own training data."""
import json

import numpy as np
import pytest
import torch

from align.dataset import AlignedDataset
from methods.nn.checkpoint import load_state, load_tensors
from methods.nn.config import from_dict
from methods.nn.weights import TrainingDataError
from methods.nn.train import train_method
from methods.registry import get
from methods.ssdd.config import SSDDConfig
from methods.ssdd.networks import SSDDUNet
from methods.ssdd.train import OOF_JSON, OOF_PREDICTIONS, predict_level1
from tests.conftest import assert_one_line_error
from tests.methods.nn.helpers import make_manifest, write_test_config

SPLITS = {"a": "train", "b": "train", "c": "train", "d": "train", "e": "validation", "f": "test"}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("ssdd")
    manifest = make_manifest(root / "corpus", SPLITS, frames=5)
    train_method("ssdd_lstm", dataset=manifest, config=write_test_config(root / "c.toml", epochs=1),
                 out=root / "run", device="cpu", progress=False)
    return root


def test_every_level2_training_prediction_is_out_of_fold(run):
    out = run / "run"
    record = json.loads((out / OOF_JSON).read_text())
    preds = load_tensors(out / OOF_PREDICTIONS, kind="predictions").tensors
    train = {n: AlignedDataset(run / "corpus" / n) for n, s in SPLITS.items() if s == "train"}
    by_checksum = {ds.checksum: ds for ds in train.values()}
    assert sorted(d["checksum"] for d in record["datasets"]) == sorted(by_checksum) == sorted(preds)
    cfg = from_dict(SSDDConfig, load_tensors(out / "ssdd_lstm.safetensors").meta["config"], where="run")
    folds = {}
    for d in record["datasets"]:
        ckpt = load_tensors(out / d["model"] / "checkpoint.safetensors", kind="checkpoint")
        trained_on = set(ckpt.meta["trained_on"])          # written by the trainer from the job's own data
        assert d["checksum"] not in trained_on and trained_on <= set(by_checksum)
        folds.setdefault(d["fold"], set()).add(d["checksum"])
        # the stored prediction is exactly that fold model's output: it came from a model blind to the frame
        net = SSDDUNet(cfg.level1.model)
        load_state(net, ckpt.prefixed("model/"), where=d["model"])
        again = predict_level1(net, by_checksum[d["checksum"]], cfg.level1)
        np.testing.assert_allclose(again, preds[d["checksum"]].numpy(), rtol=0, atol=1e-5)
        assert trained_on == set(by_checksum) - folds_of(record, d["fold"])
    assert len(folds) == 2 and set().union(*folds.values()) == set(by_checksum)
    # the final level-1 model (trained on everything) predicts otherwise: the OOF models were not it
    final = load_tensors(out / "ssdd_lstm.safetensors", kind="weights")
    net = SSDDUNet(cfg.level1.model)
    load_state(net, final.prefixed("level1/"), where="final")
    some = record["datasets"][0]["checksum"]
    assert np.abs(predict_level1(net, by_checksum[some], cfg.level1) - preds[some].numpy()).max() > 1e-3


def folds_of(record, fold):
    return {d["checksum"] for d in record["datasets"] if d["fold"] == fold}


def test_inference_runs_and_refuses_training_data(run):
    weights = run / "run" / "ssdd_lstm.safetensors"
    test_ds = AlignedDataset(run / "corpus" / "f")
    unet = get("ssdd_unet", weights=str(run / "run" / "ssdd_unet.safetensors"))
    lstm = get("ssdd_lstm", weights=str(weights))
    assert lstm.needs.sequence and not unet.needs.sequence and unet.learned
    for m in (unet, lstm):
        m.check_dataset(test_ds)
        with pytest.raises(TrainingDataError, match="train split"):
            m.check_dataset(AlignedDataset(run / "corpus" / "a"))
        with pytest.raises(TrainingDataError, match="validation split"):
            m.check_dataset(AlignedDataset(run / "corpus" / "e"))
    depth = test_ds.lq_depth(0)
    out = unet.denoise(depth)
    assert out.shape == depth.shape and np.array_equal(np.isnan(out), np.isnan(depth))
    seq = list(lstm.denoise_sequence(
        __import__("methods.base", fromlist=["FrameInput"]).FrameInput(i, test_ds.lq_depth(i)) for i in range(3)))
    assert len(seq) == 3 and all(np.isfinite(s[np.isfinite(depth)]).all() for s in seq[:1])
    with torch.no_grad():
        assert "WARNING" not in unet.provenance()


def test_bench_scores_learned_columns_and_refuses_training_frames(run, cli, tmp_path):
    w = [f"--param", f"ssdd_unet.weights={run / 'run' / 'ssdd_unet.safetensors'}",
         "--param", f"ssdd_lstm.weights={run / 'run' / 'ssdd_lstm.safetensors'}"]
    r = cli("bench", "run", "--data", run / "corpus" / "f", "--methods", "raw,ssdd_unet,ssdd_lstm", "--jobs", "1",
            "--out", tmp_path / "ok", *w)
    assert r.returncode == 0, r.stderr
    board = (tmp_path / "ok" / "leaderboard.md").read_text()
    assert "Learned methods" in board and "synthetic" in board and "ssdd_lstm.safetensors" in board
    r = cli("bench", "run", "--data", run / "corpus" / "a", "--methods", "raw,ssdd_unet", "--jobs", "1",
            "--out", tmp_path / "leak", *w[:2])
    assert_one_line_error(r, "train split")
    assert not (tmp_path / "leak").exists()
    r = cli("bench", "run", "--data", run / "corpus" / "a", "--methods", "raw,ssdd_unet", "--jobs", "1",
            "--out", tmp_path / "allowed", "--allow-train-frames", *w[:2])
    assert r.returncode == 0, r.stderr
    board = (tmp_path / "allowed" / "leaderboard.md").read_text()
    assert "WARNING" in board and "allow_train_frames=True" in board


def test_fold_mean_feeds_level2_the_mean_of_the_fold_models(tmp_path, monkeypatch):
    """``level2.level1_input = "fold_mean"``: the weights carry the k fold models exactly as trained
    (their checkpoints), and ``ssdd_lstm`` feeds level 2 the mean of their predictions, not the final
    model's: checked against level 2 run by hand on the fold checkpoints' mean. With two torch threads, the
    inference lanes give the same depth as the path without them."""
    from methods.base import FrameInput
    from methods.ssdd.model import level1_depth, level2_step
    from methods.ssdd.networks import SSDDLSTMUNet

    manifest = make_manifest(tmp_path / "corpus", SPLITS, frames=4)
    config = write_test_config(tmp_path / "c.toml", epochs=1)
    config.write_text(config.read_text() + '\n[level2]\nlevel1_input = "fold_mean"\n')
    train_method("ssdd_lstm", dataset=manifest, config=config, out=tmp_path / "run", device="cpu", progress=False)
    weights = load_tensors(tmp_path / "run" / "ssdd_lstm.safetensors", kind="weights")
    cfg = from_dict(SSDDConfig, weights.meta["config"], where="run")
    assert cfg.level2.level1_input == "fold_mean"
    depth = AlignedDataset(tmp_path / "corpus" / "f").lq_depth(0)
    d = torch.from_numpy(depth)[None, None]
    preds = []
    for f in range(cfg.folds):
        ckpt = load_tensors(tmp_path / "run" / "level1" / f"fold{f}" / "checkpoint.safetensors", kind="checkpoint")
        stored = weights.prefixed(f"level1_fold{f}/")
        assert stored.keys() == ckpt.prefixed("model/").keys()
        assert all(torch.equal(stored[k], v) for k, v in ckpt.prefixed("model/").items())
        net = SSDDUNet(cfg.level1.model)
        load_state(net, ckpt.prefixed("model/"), where="fold")
        with torch.no_grad():
            preds.append(level1_depth(net.eval(), d, None, cfg.level1.data))
    level2 = SSDDLSTMUNet(cfg.level2.model)
    load_state(level2, weights.prefixed("level2/"), where="level2")
    with torch.no_grad():
        expect, _ = level2_step(level2.eval(), torch.stack(preds).mean(0), d, None, cfg.level2.data, None)
        final = SSDDUNet(cfg.level1.model)
        load_state(final, weights.prefixed("level1/"), where="final")
        other, _ = level2_step(level2, level1_depth(final.eval(), d, None, cfg.level1.data), d, None,
                               cfg.level2.data, None)
    lstm = get("ssdd_lstm", weights=str(tmp_path / "run" / "ssdd_lstm.safetensors"))
    out, _ = lstm.denoise_step(FrameInput(0, depth), lstm.start_sequence())
    ok = np.isfinite(depth)
    np.testing.assert_allclose(out[ok], expect[0, 0].numpy()[ok], rtol=0, atol=1e-5)
    assert np.abs(out[ok] - other[0, 0].numpy()[ok]).max() > 1e-5      # not what the final model would feed
    _lanes_match_the_plain_path(tmp_path / "run", AlignedDataset(tmp_path / "corpus" / "f"), monkeypatch)


def _lanes_match_the_plain_path(run, ds, monkeypatch):
    """The trained models on two torch threads: the fold models (ssdd_lstm) and the frames of a batch (ssdd_unet)
    side by side on lanes (methods/nn/lanes.py) give the depth of the path without lanes, to 1e-4 of the code."""
    from methods.base import FrameInput
    from methods.nn.lanes import ENV
    from tests.methods.nn.helpers import torch_threads

    frames = [FrameInput(i, ds.lq_depth(i)) for i in range(4)]
    outs = {}
    with torch_threads(2):
        for mode in ("0", "1"):
            monkeypatch.setenv(ENV, mode)
            unet = get("ssdd_unet", weights=str(run / "ssdd_unet.safetensors"))
            lstm = get("ssdd_lstm", weights=str(run / "ssdd_lstm.safetensors"))
            outs[mode] = unet.denoise_batch(frames) + list(lstm.denoise_sequence(frames))
            assert unet.runtime["lanes"].lanes == lstm.runtime["lanes"].lanes == int(mode) + 1
    for plain, laned in zip(outs["0"], outs["1"]):
        assert np.array_equal(np.isnan(plain), np.isnan(laned))
        assert np.nanmax(np.abs(plain - laned)) < 1e-5


@pytest.mark.parametrize("seed", range(8))
def test_folds_are_stratified_by_scene(seed):
    """Every fold gets its share of each scene (floor or ceil of n_scene / k), whatever the seed; each
    sequence is in exactly one fold."""
    from methods.ssdd.train import assign_folds

    scenes = ["people", "balloons", "people", "balloons", "people", "people", "balloons"]
    for k in (2, 3):
        folds = assign_folds(list(range(len(scenes))), k, seed=seed, groups=scenes)
        assert sorted(set(folds)) == list(range(k))
        for scene in set(scenes):
            n = scenes.count(scene)
            counts = [sum(1 for f, s in zip(folds, scenes) if f == g and s == scene) for g in range(k)]
            assert sum(counts) == n and max(counts) - min(counts) <= 1, (k, scene, counts)
