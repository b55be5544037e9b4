"""The trainer: one seed twice gives the same weights; resume equals an uninterrupted run;
two torchrun processes (gloo) give the weights of one process with the same global batch."""
import json
import os
import subprocess
import sys

import pytest
import torch

from methods.nn.checkpoint import load_tensors
from methods.nn.train import train_method
from tests.methods.nn.helpers import make_manifest, write_test_config

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return make_manifest(tmp_path_factory.mktemp("corpus"), {"a": "train", "b": "train", "c": "validation"}, frames=4)


def _weights(run):
    return load_tensors(run / "ssdd_unet.safetensors", kind="weights").tensors


def _train(corpus, out, cfg, **kw):
    return train_method("ssdd_unet", dataset=corpus, config=cfg, out=out, device="cpu", progress=False, **kw)


def test_same_seed_same_weights_other_seed_other_weights(tmp_path, corpus):
    cfg = write_test_config(tmp_path / "c.toml")
    _train(corpus, tmp_path / "r1", cfg)
    _train(corpus, tmp_path / "r2", cfg)
    a, b = _weights(tmp_path / "r1"), _weights(tmp_path / "r2")
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    _train(corpus, tmp_path / "r3", write_test_config(tmp_path / "c3.toml", seed=1))
    c = _weights(tmp_path / "r3")
    assert not all(torch.equal(a[k], c[k]) for k in a)
    hist = (tmp_path / "r1" / "level1" / "final" / "history.csv").read_text().splitlines()
    assert hist[0].startswith("epoch,train_loss,val_loss") and len(hist) == 3
    assert (tmp_path / "r1" / "level1" / "final" / "curves.png").stat().st_size > 1000
    meta = load_tensors(tmp_path / "r1" / "ssdd_unet.safetensors").meta
    assert meta["training"]["manifest_sha256"] and meta["config"]["level1"]["model"]["width"] == 4
    assert {d["split"] for d in meta["training"]["datasets"]} == {"train", "validation"}


def test_resume_continues_to_the_same_weights(tmp_path, corpus):
    _train(corpus, tmp_path / "full", write_test_config(tmp_path / "c2.toml", epochs=2))
    _train(corpus, tmp_path / "part", write_test_config(tmp_path / "c1.toml", epochs=1))
    result = _train(corpus, tmp_path / "part", write_test_config(tmp_path / "c2.toml", epochs=2), resume=True)
    assert result.stages["level 1"]["resumed_from_epoch"] == 1
    a, b = _weights(tmp_path / "full"), _weights(tmp_path / "part")
    assert all(torch.allclose(a[k], b[k], atol=0, rtol=0) for k in a)


def test_torchrun_two_processes_equal_one(tmp_path, corpus):
    cfg = write_test_config(tmp_path / "c.toml", epochs=1)
    env = {**os.environ, "PYTHONPATH": REPO, "OMP_NUM_THREADS": "1"}
    base = ["-m", "depthbench", "methods", "train", "ssdd_unet", "--dataset", str(corpus), "--config", str(cfg),
            "--device", "cpu", "--no-progress", "--out"]
    one = subprocess.run([sys.executable, *base, str(tmp_path / "one")], env=env, capture_output=True, text=True,
                         timeout=600)
    assert one.returncode == 0, one.stderr
    two = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
                          *base, str(tmp_path / "two")], env=env, capture_output=True, text=True, timeout=600)
    assert two.returncode == 0, two.stderr[-3000:]
    a, b = _weights(tmp_path / "one"), _weights(tmp_path / "two")
    diffs = {k: (a[k] - b[k]).abs().max().item() for k in a}
    assert max(diffs.values()) < 1e-5, diffs
    assert json.loads((tmp_path / "two" / "run.json").read_text())["processes"] == 2


def test_the_cosine_schedule_anneals_the_rate_to_zero_and_the_trainer_applies_it(tmp_path, corpus):
    import math

    from methods.nn.config import OptimConfig
    from methods.nn.trainer import step_lr

    cos, const = OptimConfig(lr=2e-3, lr_schedule="cosine"), OptimConfig(lr=2e-3)
    steps = 200
    assert [step_lr(cos, s, steps) for s in range(steps)] == pytest.approx(
        [1e-3 * (1 + math.cos(math.pi * s / steps)) for s in range(steps)], rel=1e-12)
    assert step_lr(cos, 0, steps) == 2e-3 and step_lr(cos, steps - 1, steps) < 1e-4 * 2e-3
    assert all(step_lr(const, s, steps) == 2e-3 for s in range(steps))
    with pytest.raises(ValueError, match="lr_schedule"):
        OptimConfig(lr_schedule="step")
    # through a real fit: the schedule changes the weights (constant = the trainer as before: the seed tests above)
    plain = write_test_config(tmp_path / "c.toml")
    annealed = tmp_path / "cos.toml"
    annealed.write_text(plain.read_text().replace("lr = 3e-3\n", 'lr = 3e-3\nlr_schedule = "cosine"\n'))
    _train(corpus, tmp_path / "plain", plain)
    _train(corpus, tmp_path / "cos", annealed)
    a, b = _weights(tmp_path / "plain"), _weights(tmp_path / "cos")
    assert not all(torch.equal(a[k], b[k]) for k in a)
    meta = load_tensors(tmp_path / "cos" / "ssdd_unet.safetensors").meta
    assert meta["config"]["level1"]["optim"]["lr_schedule"] == "cosine"
