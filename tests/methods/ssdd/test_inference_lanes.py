"""SSDD inference on lanes (methods/nn/lanes.py; the fold models of the fold mean and the frames of a batch side
by side) gives the depth of the plain modules run by hand, one pass after another, to float rounding, on random
networks and inputs; the weights still load as tensors only."""
import numpy as np
import pytest
import torch

from methods.base import FrameInput
from methods.nn.checkpoint import load_tensors, save_tensors
from methods.nn.config import to_dict
from methods.nn.lanes import ENV
from methods.registry import get
from methods.ssdd.config import FOLD_PREFIX, Level1Config, Level2Config, SSDDConfig
from methods.ssdd.model import build_level1, build_level2, level1_depth, level2_step
from methods.ssdd.networks import NetConfig
from methods.ssdd.prefilter import PrefilterConfig, prefilter_frames
from tests.methods.nn.helpers import torch_threads

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


def _by_hand(lstm, frames: list[FrameInput]) -> tuple[list, list]:
    """Level 1 of each frame alone, and level 2 fed the fold models' mean, straight from the plain modules."""
    cfg, rt = lstm.config, lstm.runtime
    unet, steps, state = [], [], None
    with torch.no_grad():
        for f in frames:
            d = torch.from_numpy(f.depth)[None, None]
            base = prefilter_frames([f.depth], cfg.level1.prefilter)
            b = None if base is None else torch.from_numpy(base[:, None])
            unet.append(level1_depth(rt["level1"], d, None, cfg.level1.data, b))
            l1 = torch.stack([level1_depth(n, d, None, cfg.level1.data, b) for n in rt["feeders"]]).mean(0)
            y, state = level2_step(rt["level2"], l1, d, None, cfg.level2.data, state,
                                   sequence_centre=cfg.level2.centre == "sequence", motion=cfg.level2.motion)
            steps.append(y)
    keep = lambda t, f: np.where(np.isfinite(f.depth), t[0, 0].numpy(), np.nan)  # noqa: E731
    return [keep(t, f) for t, f in zip(unet, frames)], [keep(t, f) for t, f in zip(steps, frames)]


def _methods(weights, lanes: str, monkeypatch):
    monkeypatch.setenv(ENV, lanes)
    unet, lstm = get("ssdd_unet", weights=str(weights)), get("ssdd_lstm", weights=str(weights))
    unet.ensure_prepared()
    lstm.ensure_prepared()
    return unet, lstm


@pytest.mark.parametrize("prefilter", ["none", "bilateral"])
def test_lanes_give_the_plain_modules_depth(prefilter, tmp_path, monkeypatch):
    weights = tmp_path / "w.safetensors"
    _random_weights(weights, prefilter=prefilter)
    assert load_tensors(weights, kind="weights").tensors          # tensors only: loading never unpickles
    frames = _frames(5)
    with torch_threads(2):
        out = {}
        for mode in ("0", "1"):
            unet, lstm = _methods(weights, mode, monkeypatch)
            assert unet.runtime["lanes"].lanes == lstm.runtime["lanes"].lanes == (2 if mode == "1" else 1)
            state, steps = lstm.start_sequence(), []
            for f in frames:
                y, state = lstm.denoise_step(f, state)
                steps.append(y)
            out[mode] = (unet.denoise_batch(frames[:3]), steps)   # 3 frames, one at a time on 2 lanes
        hand = _by_hand(lstm, frames)
    expect = hand[0][:3] + hand[1]                                # the plain modules by hand
    assert all(np.abs(e - f.depth)[np.isfinite(e)].max() > 1e-3 for e, f in zip(expect, frames[:3] + frames))
    for mode in ("0", "1"):                                       # lanes off and on
        for got, e in zip(out[mode][0] + out[mode][1], expect):
            assert np.array_equal(np.isnan(got), np.isnan(e))
            assert np.nanmax(np.abs(got - e)) < TOL_M


def test_compile_opt_in_compiles_level1_without_lanes(tmp_path, monkeypatch):
    """``DEPTHBENCH_COMPILE=1`` (methods/nn/compiled.py): the level-1 nets (final and folds) run through
    ``torch.compile`` (here with dynamo's eager backend, to stay fast; inductor's numbers are in the worklog), level 2
    stays eager, lanes are off, and the depth is the plain modules'."""
    from methods.nn import compiled

    real = torch.compile
    monkeypatch.setattr(torch, "compile", lambda net: real(net, backend="eager"))
    monkeypatch.setenv(compiled.ENV, "1")
    weights = tmp_path / "w.safetensors"
    _random_weights(weights, prefilter="none")
    frames = _frames(3)
    with torch_threads(2):
        unet, lstm = _methods(weights, "1", monkeypatch)
        got = unet.denoise_batch(frames) + list(lstm.denoise_sequence(frames))
        monkeypatch.setenv(compiled.ENV, "0")
        hand = _by_hand(_methods(weights, "1", monkeypatch)[1], frames)
    is_compiled = lambda net: isinstance(net, torch._dynamo.eval_frame.OptimizedModule)  # noqa: E731
    assert is_compiled(unet.runtime["level1"]) and all(is_compiled(f) for f in lstm.runtime["feeders"])
    assert len(lstm.runtime["feeders"]) == 2 and not is_compiled(lstm.runtime["level2"])
    assert unet.runtime["lanes"].lanes == lstm.runtime["lanes"].lanes == 1
    for g, e in zip(got, hand[0] + hand[1]):
        assert np.array_equal(np.isnan(g), np.isnan(e)) and np.nanmax(np.abs(g - e)) < TOL_M
