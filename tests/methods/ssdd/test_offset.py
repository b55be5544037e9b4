"""``level2.offset = "level1"`` (methods.ssdd.model.offset_free_target, not in the paper): the shifted reference
against a direct per-image median, level 2's loss equal to eq. 32 against it, blind to a uniform shift of the
reference (which the paper's loss is not), and the option checked and named on the leaderboard."""
import numpy as np
import pytest
import torch

from methods.nn.config import ConfigError, from_dict
from methods.ssdd.config import Level2Config, SSDDConfig
from methods.ssdd.denoise import SSDDLSTMDenoiser
from methods.ssdd.model import build_level2, level2_depth, level2_loss, offset_free_target
from methods.ssdd.networks import NetConfig


def _arrays(rng, shape):
    level1 = rng.uniform(1.0, 3.0, shape)
    ref = level1 + rng.normal(0.004, 0.01, shape)
    ref[rng.random(shape) < 0.15] = np.nan
    mask = (rng.random(shape) < 0.7).astype(np.float64)
    mask[1, 2] = 0.0                                       # an image with no loss pixel: left as it is
    return level1, ref, mask


def _direct(level1, ref, mask):
    """ref - the lower median of (ref - level1) over each image's mask pixels, by a loop over images."""
    want = ref.copy()
    for b, t in np.ndindex(ref.shape[:2]):
        keep = (mask[b, t] > 0) & np.isfinite(ref[b, t])
        vals = np.sort((ref[b, t] - level1[b, t])[keep])
        if vals.size:
            want[b, t] = ref[b, t] - vals[(vals.size - 1) // 2]
    return want


def test_the_offset_free_target_subtracts_each_images_median_residual_against_a_direct_loop():
    rng = np.random.default_rng(3)
    level1, ref, mask = _arrays(rng, (2, 3, 1, 7, 9))
    t = torch.from_numpy
    got = offset_free_target(t(ref), t(level1), t(mask)).numpy()
    np.testing.assert_allclose(got, _direct(level1, ref, mask), rtol=0, atol=1e-12, equal_nan=True)
    np.testing.assert_array_equal(got[1, 2], ref[1, 2])
    assert np.abs(got - ref)[np.isfinite(ref)].max() > 1e-3  # it does shift the other images


def _loss_case(seed):
    torch.manual_seed(0)
    rng = np.random.default_rng(seed)
    cfg = Level2Config(model=NetConfig(width=4, levels=2, recurrent=[-1]))
    shape = (2, 3, 1, 12, 16)
    level1, ref, mask = _arrays(rng, shape)
    lq = level1 + rng.normal(0, 0.01, shape)
    lq[rng.random(shape) < 0.1] = np.nan
    f = lambda a: torch.from_numpy(np.asarray(a, np.float32))  # noqa: E731
    batch = {"lq_depth": f(lq), "reference": f(ref), "roi": f(mask), "valid": f(np.isfinite(ref)), "color": None,
             "level1": f(level1)}
    return cfg, build_level2(cfg), batch


def test_level2s_loss_with_offset_level1_is_eq32_against_that_target_and_blind_to_a_uniform_shift():
    cfg, net, batch = _loss_case(5)
    loss = level2_loss(cfg.data, offset="level1")
    pred = level2_depth(net, batch["level1"], batch["lq_depth"], None, cfg.data).detach().numpy().astype(np.float64)
    m = batch["roi"].numpy() * np.isfinite(batch["lq_depth"].numpy())          # eq. 32's pixels (no holes)
    target = _direct(batch["level1"].numpy().astype(np.float64), batch["reference"].numpy().astype(np.float64), m)
    keep = (m > 0) & np.isfinite(target)
    assert loss(net, batch).item() == pytest.approx(np.abs(pred - target)[keep].sum() / pred.size, rel=1e-4)
    shifted = dict(batch, reference=batch["reference"] + torch.tensor([0.03, -0.02, 0.05]).view(1, 3, 1, 1, 1))
    assert loss(net, shifted).item() == pytest.approx(loss(net, batch).item(), rel=1e-5)
    free = level2_loss(cfg.data)
    assert abs(free(net, shifted).item() - free(net, batch).item()) > 0.2 * free(net, batch).item()


def test_the_offset_option_is_checked_and_named_on_the_leaderboard():
    with pytest.raises(ConfigError, match="level2.offset"):
        from_dict(SSDDConfig, {"level2": {"offset": "zero"}}, where="c.toml")
    assert from_dict(SSDDConfig, {"level2": {"offset": "level1"}}, where="c.toml").level2.offset == "level1"
    assert SSDDConfig().level2.offset == "free"            # the paper's loss by default
    assert "level2.offset" in SSDDLSTMDenoiser.not_in_paper
