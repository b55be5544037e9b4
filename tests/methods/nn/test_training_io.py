"""Configs, checkpoints and manifests: bad input is a one-line error, exit 2, nothing half-written."""
import json
import pickle

import pytest
import torch

from methods.errors import CheckpointError, ConfigError, TrainingManifestError
from methods.nn.checkpoint import load_state, load_tensors, save_tensors
from methods.nn.config import from_dict, load_config, to_toml
from methods.nn.manifest import read_manifest
from methods.ssdd.config import SSDDConfig
from tests.conftest import assert_one_line_error
from tests.methods.nn.helpers import make_manifest


def test_builtin_configs_load_and_round_trip(tmp_path):
    for name in ("tiny", "paper"):
        cfg, path = load_config(name, SSDDConfig, family="ssdd")
        assert path.name == f"{name}.toml"
        f = tmp_path / f"{name}.toml"
        f.write_text(to_toml(cfg))
        assert load_config(f, SSDDConfig, family="ssdd")[0] == cfg


@pytest.mark.parametrize("text, fragment", [
    ("[level1.model]\nwidht = 8\n", "unknown key 'level1.model.widht'"),
    ("folds = 'two'\n", "folds must be an int"),
    ("folds = 1\n", "folds must be at least 2"),
    ("[level1.data]\ncrop = 30\n", "multiple of 8"),
    ("folds = \n", "not valid TOML"),
])
def test_bad_config_is_one_line(tmp_path, text, fragment):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(ConfigError) as exc:
        load_config(f, SSDDConfig, family="ssdd")
    assert fragment in str(exc.value) and "\n" not in str(exc.value)


def test_checkpoint_round_trip_and_refusals(tmp_path):
    net = torch.nn.Conv2d(1, 2, 3)
    p = tmp_path / "w.safetensors"
    save_tensors(p, net.state_dict(), kind="weights", meta={"config": {"a": [1, 2]}})
    f = load_tensors(p, kind="weights")
    assert f.meta["config"] == {"a": [1, 2]} and len(f.sha256) == 64
    other = torch.nn.Conv2d(1, 2, 3)
    load_state(other, f.tensors, where=p)
    assert torch.equal(other.weight, net.weight)
    with pytest.raises(CheckpointError, match="expected 'checkpoint'"):
        load_tensors(p, kind="checkpoint")
    with pytest.raises(CheckpointError, match="shape"):
        load_state(torch.nn.Conv2d(1, 3, 3), f.tensors, where=p)
    # a pickle (what torch.save writes) is refused without being unpickled
    evil = tmp_path / "evil.safetensors"
    evil.write_bytes(pickle.dumps({"weight": torch.zeros(2)}))
    with pytest.raises(CheckpointError, match="never unpickled"):
        load_tensors(evil)
    torch.save(net.state_dict(), tmp_path / "torch.pt")
    with pytest.raises(CheckpointError, match="not a readable safetensors"):
        load_tensors(tmp_path / "torch.pt")
    data = bytearray(p.read_bytes())
    (tmp_path / "cut.safetensors").write_bytes(bytes(data[: len(data) // 2]))
    with pytest.raises(CheckpointError):
        load_tensors(tmp_path / "cut.safetensors")
    from safetensors.torch import save_file
    save_file({"x": torch.zeros(1)}, str(tmp_path / "foreign.safetensors"))
    with pytest.raises(CheckpointError, match="not a depthbench weights file"):
        load_tensors(tmp_path / "foreign.safetensors")


def test_manifest_checks_datasets(tmp_path):
    path = make_manifest(tmp_path / "c", {"a": "train", "b": "validation"}, frames=2)
    m = read_manifest(path)
    assert [d.name for d in m.split("train")] == ["a"] and [d.name for d in m.split("validation")] == ["b"]
    meta = json.loads(path.read_text())
    meta["datasets"][1]["path"] = "gone"
    path.write_text(json.dumps(meta))
    with pytest.raises(TrainingManifestError, match="'b'.*missing"):
        read_manifest(path)
    meta["datasets"][1]["path"] = "../../etc"
    path.write_text(json.dumps(meta))
    with pytest.raises(TrainingManifestError, match="escapes"):
        read_manifest(path)
    meta["datasets"][1]["path"] = "b"
    meta["datasets"][1]["checksum"] = "0" * 64
    path.write_text(json.dumps(meta))
    with pytest.raises(TrainingManifestError, match="has changed"):
        read_manifest(path)


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return make_manifest(tmp_path_factory.mktemp("corpus"), {"a": "train", "b": "train", "c": "validation"}, frames=3)


@pytest.mark.parametrize("case", ["missing_dataset", "unknown_key", "corrupt_checkpoint", "pickled_checkpoint"])
def test_train_cli_bad_inputs(cli, tmp_path, corpus, case):
    manifest = corpus
    config = "tiny"
    out = tmp_path / "run"
    args = []
    if case == "missing_dataset":
        meta = json.loads(corpus.read_text())
        meta["datasets"][0]["path"] = "nowhere"
        manifest = corpus.parent / "broken.json"
        manifest.write_text(json.dumps(meta))
        fragment = "nowhere is missing"
    elif case == "unknown_key":
        config = tmp_path / "c.toml"
        config.write_text("[level2.optim]\nepochz = 3\n")
        fragment = "unknown key 'level2.optim.epochz'"
    else:   # an existing run whose checkpoint is damaged: --resume refuses before writing anything
        (out / "level1" / "final").mkdir(parents=True)
        (out / "run.json").write_text(json.dumps({"method": "ssdd_unet"}))
        bad = out / "level1" / "final" / "checkpoint.safetensors"
        bad.write_bytes(b"\x00garbage" * 10 if case == "corrupt_checkpoint" else pickle.dumps({"w": [1.0]}))
        args = ["--resume"]
        fragment = "checkpoint.safetensors"
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    stamp = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    r = cli("methods", "train", "ssdd_unet", "--dataset", manifest, "--config", config, "--out", out,
            "--no-progress", *args)
    assert_one_line_error(r, fragment)
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before
    assert all(p.read_bytes() == b for p, b in stamp.items())


def test_from_dict_rejects_non_table():
    with pytest.raises(ConfigError, match="must be a table"):
        from_dict(SSDDConfig, {"level1": 3}, where="x")
