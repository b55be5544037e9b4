"""SSDD learns to denoise (the regression test of why it stayed at the identity): ssdd_unet trained
for real by ``train_method`` with the ``tiny`` recipe (centred coding, no GroupNorm, ROI-centred crops,
full-resolution stem) on synthetic sequences, scored on a held-out sequence against its truth."""
import numpy as np
import pytest

from align.dataset import AlignedDataset
from methods.nn.train import train_method
from methods.registry import get
from tests.methods.nn.helpers import make_manifest

SPLITS = {"a": "train", "b": "train", "c": "train", "d": "validation", "held": "test"}

CONFIG = """\
folds = 2
[level1.model]
width = 8
levels = 3
[level1.data]
crop = 32
roi_crop = 0.8
depth_scale_m = 0.1
validation_stride = 4
[level1.optim]
epochs = 12
batch_size = 8
samples_per_epoch = 160
lr = 2e-3
"""


def _mse(out, truth, ok):
    return float(np.mean((out[ok] - truth[ok]) ** 2))


PREFILTER = """
[level1.prefilter]
kind = "bilateral"
"""


@pytest.mark.parametrize("prefilter", [False, True], ids=["plain", "bilateral_prefilter"])
def test_tiny_recipe_ssdd_unet_beats_raw_and_the_bilateral_filter_on_held_out_truth(tmp_path, prefilter):
    manifest = make_manifest(tmp_path / "corpus", SPLITS, frames=8)
    (tmp_path / "c.toml").write_text(CONFIG + (PREFILTER if prefilter else ""))
    train_method("ssdd_unet", dataset=manifest, config=tmp_path / "c.toml", out=tmp_path / "run", device="cpu",
                 progress=False)
    net = get("ssdd_unet", weights=str(tmp_path / "run" / "ssdd_unet.safetensors"))
    bf = get("bf")
    held = AlignedDataset(tmp_path / "corpus" / "held")
    scores = {"raw": [], "bf": [], "ssdd_unet": []}
    for i in range(len(held)):
        depth, truth = held.lq_depth(i), held.truth(i)
        ok = np.isfinite(depth) & np.isfinite(truth)
        scores["raw"].append(_mse(depth, truth, ok))
        scores["bf"].append(_mse(bf.denoise(depth), truth, ok))
        scores["ssdd_unet"].append(_mse(net.denoise(depth), truth, ok))
    mean = {k: np.mean(v) for k, v in scores.items()}
    assert mean["ssdd_unet"] < 0.5 * mean["raw"], mean
    assert mean["ssdd_unet"] < mean["bf"], mean
