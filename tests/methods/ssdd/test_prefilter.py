"""Level 1's bilateral prefilter (methods.ssdd.prefilter): the net corrects the filtered LQ depth, with
the filter's parameters taken from the weights' config, through training and the Denoiser alike."""
import numpy as np
import pytest
import torch

from methods.bilateral import bilateral_filter
from methods.nn.checkpoint import save_tensors
from methods.nn.config import ConfigError, DataConfig, from_dict, to_dict
from methods.registry import get
from methods.ssdd.config import Level1Config, Level2Config, SSDDConfig
from methods.ssdd.model import level1_depth
from methods.ssdd.networks import NetConfig, SSDDLSTMUNet, SSDDUNet
from methods.ssdd.prefilter import PrefilterConfig, prefilter
from methods.tools.synthetic import synthetic_scene

PRE = PrefilterConfig(kind="bilateral", sigma_spatial=2.0, sigma_color=0.03, depth_adaptive=True)


def _weights(path, pre: PrefilterConfig, *, head: float):
    """A weights file of untrained nets whose level-1 and level-2 heads are scaled by ``head``."""
    cfg = SSDDConfig(level1=Level1Config(model=NetConfig(width=4, levels=2), data=DataConfig(depth_scale_m=0.1),
                                         prefilter=pre),
                     level2=Level2Config(model=NetConfig(width=4, levels=2, recurrent=[-1]),
                                         data=DataConfig(depth_scale_m=0.1, sequence_length=2)))
    torch.manual_seed(0)
    l1, l2 = SSDDUNet(cfg.level1.model, base=pre.enabled), SSDDLSTMUNet(cfg.level2.model)
    with torch.no_grad():
        for net in (l1, l2):
            net.unet.head.weight.mul_(head)
            net.unet.head.bias.zero_()
    tensors = {**{f"level1/{k}": v for k, v in l1.state_dict().items()},
               **{f"level2/{k}": v for k, v in l2.state_dict().items()}}
    save_tensors(path, tensors, kind="weights", meta={"method": "ssdd_lstm", "config": to_dict(cfg),
                                                      "training": {"datasets": []}})
    return str(path)


@pytest.fixture(scope="module")
def depth():
    _, d = synthetic_scene((60, 80), seed=3)
    return d


@pytest.mark.parametrize("method", ["ssdd_unet", "ssdd_lstm"])
def test_an_untrained_prefiltered_level1_is_the_configured_bilateral_filter(tmp_path, depth, method):
    """With a zero correction the output is exactly the bilateral filter of the config's parameters
    (the base is coded and decoded with the LQ frame's centre), NaN at the LQ holes; without a
    prefilter it is the raw depth."""
    assert np.isnan(depth).any()
    expect = bilateral_filter(depth, sigma_spatial=2.0, sigma_color=0.03, depth_adaptive=True)
    den = get(method, weights=_weights(tmp_path / "w.safetensors", PRE, head=0.0))
    out = den.denoise(depth) if method == "ssdd_unet" else den.denoise_step(_frame(depth), den.start_sequence())[0]
    ok = np.isfinite(depth)
    np.testing.assert_allclose(out[ok], expect[ok], rtol=0, atol=2e-6)
    assert np.isnan(out[~ok]).all()
    other = bilateral_filter(depth)                       # the default parameters give another base
    assert np.abs(other[ok] - expect[ok]).max() > 1e-3
    plain = get(method, weights=_weights(tmp_path / "p.safetensors", PrefilterConfig(), head=0.0))
    out = plain.denoise(depth) if method == "ssdd_unet" else plain.denoise_step(_frame(depth), None)[0]
    np.testing.assert_allclose(out[ok], depth[ok], rtol=0, atol=2e-6)


def _frame(depth):
    from methods.base import FrameInput
    return FrameInput(0, depth)


def test_the_correction_is_added_to_the_base_and_sees_the_raw_depth(depth):
    """A non-zero head: the output moves away from the base, and it depends on the raw LQ depth too
    (the net is fed both), so two LQ frames with one base give two outputs."""
    torch.manual_seed(0)
    net = SSDDUNet(NetConfig(width=4, levels=2), base=True)
    with torch.no_grad():
        net.unet.head.weight.mul_(100)
    d = torch.from_numpy(depth)[None, None]
    base = torch.from_numpy(prefilter(depth, PRE))[None, None]
    data = DataConfig(depth_scale_m=0.1)
    out = level1_depth(net, d, None, data, base)
    ok = torch.isfinite(d)
    assert (out - base)[ok].abs().max() > 1e-3
    noisier = d + 0.01 * torch.randn(d.shape, generator=torch.Generator().manual_seed(1))
    assert (level1_depth(net, noisier, None, data, base) - out)[ok].abs().max() > 1e-5
    with pytest.raises(ValueError, match="needs"):
        net(d.nan_to_num(), ok.float())


def test_the_prefilter_config_is_checked():
    with pytest.raises(ConfigError, match="prefilter.kind"):
        from_dict(SSDDConfig, {"level1": {"prefilter": {"kind": "median"}}}, where="c.toml")
    assert prefilter(np.ones((4, 4), np.float32), PrefilterConfig()) is None
