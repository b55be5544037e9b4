"""DDRNet trained for real through ``methods train`` on small synthetic aligned datasets (a disc in
front of a slanted wall; LQ = truth + 2 % noise + holes, reference = truth + 1 mm): it beats the raw
depth against truth on a held-out dataset, one seed gives the same weights twice. (The simulator-based
runs, slower, are in the closing note with their learning curves.)"""
from __future__ import annotations

import numpy as np

from align.dataset import AlignedDataset
from methods.nn.checkpoint import load_tensors
from methods.nn.train import train_method
from methods.registry import get
from tests.methods.nn.helpers import make_manifest, scene_dataset

CONFIG = """methods = ["ddrnet", "ddrnet_refine"]
[model]
width = 8
refine_width = 8
[loss]
foreground_only = false
[data]
crop = 32
depth_min_m = 0.5
depth_max_m = 4.0
[optim]
epochs = {epochs}
batch_size = 4
samples_per_epoch = 32
lr = 2e-3
seed = 0
"""


def _mae_mm(ds: AlignedDataset, method) -> float:
    err = []
    for i in range(len(ds)):
        f = ds.frame(i)
        color = np.zeros(f.lq_depth.shape + (3,), np.uint8) + 128
        out = method.denoise(f.lq_depth, color, ds.lq_intrinsics)
        ok = np.isfinite(f.lq_depth) & np.isfinite(out)
        err.append(np.abs(out - f.truth)[ok])
    return 1000 * float(np.concatenate(err).mean())


def test_ddrnet_trained_beats_raw_on_held_out_data_and_is_reproducible(tmp_path):
    manifest = make_manifest(tmp_path / "corpus", {"a": "train", "b": "train", "c": "validation"}, frames=6)
    test = AlignedDataset(scene_dataset(tmp_path / "test", name="test", frames=4, seed=7))
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(CONFIG.format(epochs=6))
    run = train_method("ddrnet", dataset=manifest, config=cfg, out=tmp_path / "run", device="cpu", progress=False)
    raw = _mae_mm(test, get("raw"))
    for name in ("ddrnet", "ddrnet_refine"):
        history = (tmp_path / "run" / name / "history.csv").read_text().splitlines()
        assert len(history) == 7 and "train_rec" in history[0]
        mae = _mae_mm(test, get(name, weights=str(run.weights[name])))
        assert mae < 0.8 * raw, (name, mae, raw)
    short = tmp_path / "short.toml"
    short.write_text(CONFIG.format(epochs=1))
    a = train_method("ddrnet", dataset=manifest, config=short, out=tmp_path / "a", device="cpu", progress=False)
    b = train_method("ddrnet", dataset=manifest, config=short, out=tmp_path / "b", device="cpu", progress=False)
    for name in ("ddrnet", "ddrnet_refine"):
        ta, tb = load_tensors(a.weights[name]).tensors, load_tensors(b.weights[name]).tensors
        assert ta.keys() == tb.keys() and all(bool((ta[k] == tb[k]).all()) for k in ta), name


def test_ddrnet_config_draws_roi_crops_for_training_only_strides_validation_and_refuses_the_centred_coding(tmp_path):
    import pytest

    from methods.ddrnet.train import DDRNetConfig, _samples
    from methods.errors import ConfigError
    from methods.nn.config import from_dict, load_config

    tiny, _ = load_config("tiny", DDRNetConfig, family="ddrnet")
    ds = [AlignedDataset(scene_dataset(tmp_path / "a", name="a", frames=12))]
    assert tiny.data.roi_crop > 0 and tiny.data.validation_stride == 10
    tiny.data.crop = 32  # the synthetic frames are 48x40
    assert _samples(ds, tiny, train=True).roi_crop == tiny.data.roi_crop and len(_samples(ds, tiny, train=True)) == 12
    val = _samples(ds, tiny, train=False)
    assert val.roi_crop == 0.0 and val.crop == 0 and len(val) == 2   # frames 0 and 10: every 10th validation frame
    with pytest.raises(ConfigError, match="depth_scale_m must be 0"):
        from_dict(DDRNetConfig, {"data": {"depth_scale_m": 0.1}}, where="cfg.toml")
