"""SSDD inference on lanes (methods/nn/lanes.py; the fold models of the fold mean and the frames of a batch side
by side) gives the one-after-another path's depth to float rounding, on random networks and inputs; the weights
still load as tensors only."""
import numpy as np
import pytest
import torch

from methods.base import FrameInput
from methods.nn.checkpoint import load_tensors, save_tensors
from methods.nn.config import to_dict
from methods.nn.lanes import ENV
from methods.registry import get
from methods.ssdd.config import FOLD_PREFIX, Level1Config, Level2Config, SSDDConfig
from methods.ssdd.model import build_level1, build_level2
from methods.ssdd.networks import NetConfig
from methods.ssdd.prefilter import PrefilterConfig

# 1e-4 of the depth code (depth_scale_m = 0.1 m per unit) in metres
TOL_M = 1e-5


def _random_weights(path, *, prefilter: str) -> None:
    """An ``ssdd_lstm`` weights file (fold mean, 2 folds) of random networks whose corrections are not small."""
    net = NetConfig(width=4, levels=3, norm="none")
    cfg = SSDDConfig(level1=Level1Config(model=net, prefilter=PrefilterConfig(kind=prefilter)),
                     level2=Level2Config(model=NetConfig(width=4, levels=3, norm="none", recurrent=[-1]),
                                         level1_input="fold_mean"))
    gen = torch.Generator().manual_seed(3)

    def state(module):
        return {k: torch.randn(v.shape, generator=gen) * 0.2 for k, v in module.state_dict().items()}

    tensors = {f"level1/{k}": v for k, v in state(build_level1(cfg.level1)).items()}
    tensors.update({f"level2/{k}": v for k, v in state(build_level2(cfg.level2)).items()})
    for f in range(cfg.folds):
        tensors.update({f"{FOLD_PREFIX}{f}/{k}": v for k, v in state(build_level1(cfg.level1)).items()})
    save_tensors(path, tensors, kind="weights", meta={"method": "ssdd_lstm", "config": to_dict(cfg),
                                                       "training": {"datasets": []}})


def _frames(n: int, shape=(37, 45)) -> list[FrameInput]:
    rng = np.random.default_rng(5)
    out = []
    for i in range(n):
        d = (1.5 + 0.3 * rng.random(shape) + 0.02 * rng.standard_normal(shape)).astype(np.float32)
        d[rng.random(shape) < 0.1] = np.nan
        out.append(FrameInput(i, d))
    return out


def _methods(weights, lanes: str, monkeypatch):
    monkeypatch.setenv(ENV, lanes)
    unet, lstm = get("ssdd_unet", weights=str(weights)), get("ssdd_lstm", weights=str(weights))
    unet.ensure_prepared()
    lstm.ensure_prepared()
    return unet, lstm


@pytest.mark.parametrize("prefilter", ["none", "bilateral"])
def test_lanes_give_the_plain_paths_depth(prefilter, tmp_path, monkeypatch):
    weights = tmp_path / "w.safetensors"
    _random_weights(weights, prefilter=prefilter)
    assert load_tensors(weights, kind="weights").tensors          # tensors only: loading never unpickles
    frames = _frames(5)
    n = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        out = {}
        for mode in ("0", "1"):
            unet, lstm = _methods(weights, mode, monkeypatch)
            assert unet.runtime["lanes"].lanes == lstm.runtime["lanes"].lanes == (2 if mode == "1" else 1)
            state, steps = lstm.start_sequence(), []
            for f in frames:
                y, state = lstm.denoise_step(f, state)
                steps.append(y)
            out[mode] = (unet.denoise_batch(frames[:3]), steps)   # 3 frames, one at a time on 2 lanes
    finally:
        torch.set_num_threads(n)
    for plain, laned, f in zip(out["0"][0] + out["0"][1], out["1"][0] + out["1"][1], frames[:3] + frames):
        assert np.array_equal(np.isnan(plain), np.isnan(f.depth)) and np.array_equal(np.isnan(laned), np.isnan(plain))
        ok = np.isfinite(plain)
        assert np.abs(plain[ok] - f.depth[ok]).max() > 1e-3        # the networks do change the depth
        assert np.abs(laned[ok] - plain[ok]).max() < TOL_M
