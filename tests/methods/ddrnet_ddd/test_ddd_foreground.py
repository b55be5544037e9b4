"""DDD's foreground-weighted eq. 22 (an option): the split mean against a direct formula, and each
view's foreground found from its own depth marks a moving disc (simulator-free truth: the disc's
pixels are known), never reading the reference or the truth."""
from __future__ import annotations

import numpy as np
import torch

from methods.ddd.losses import DDDLoss, masked_mean, split_mean
from methods.ddd.model import LossConfig
from methods.ddd.multiview import MultiViewSamples, rig_groups
from align.dataset import AlignedDataset
from tests.methods.ddrnet_ddd.test_ddd_training import _rig_session


def test_split_mean_weights_foreground_and_background_means_as_a_direct_formula():
    g = torch.Generator().manual_seed(0)
    x = torch.rand(2, 1, 6, 7, generator=g)
    mask = torch.rand(2, 1, 6, 7, generator=g) > 0.3
    fg = torch.rand(2, 1, 6, 7, generator=g) > 0.7
    xs, ms, fs = x.numpy().ravel(), mask.numpy().ravel(), fg.numpy().ravel()
    want = 0.8 * xs[ms & fs].mean() + 0.2 * xs[ms & ~fs].mean()
    assert abs(float(split_mean(x, mask, fg, weight=0.8)) - want) < 1e-6
    plain = xs[ms].mean()
    assert abs(float(split_mean(x, mask, fg, weight=0.0)) - plain) < 1e-6          # the paper: every pixel alike
    assert abs(float(split_mean(x, mask, None, weight=0.8)) - plain) < 1e-6
    none = torch.zeros_like(fg)
    assert abs(float(split_mean(x, mask, none, weight=0.8)) - plain) < 1e-6        # no foreground: plain mean
    assert abs(want - plain) > 1e-3                                                # the weighting changes it here


def test_loss_with_foreground_weight_counts_foreground_errors_more():
    """Same total error, once on the foreground and once on the background: the weighted loss ranks them."""
    d = torch.full((1, 1, 8, 8), 2.0)
    valid = torch.ones(1, 1, 8, 8, dtype=torch.bool)
    fg = torch.zeros_like(valid)
    fg[..., 2:4, 2:4] = True
    err_fg, err_bg = d.clone(), d.clone()
    err_fg[fg] += 0.05
    err_bg[..., 6:8, 6:8] += 0.05
    module = LossConfig(foreground_weight=0.8).module()
    img = torch.rand(1, 3, 8, 8, generator=torch.Generator().manual_seed(1))
    normals = (torch.tensor([0.0, 0.0, -1.0]).view(1, 3, 1, 1).expand(1, 3, 8, 8), valid)

    def loss(pred, *, foreground):
        return module(rendered=[img], targets=[img], photo_masks=[valid], preds=[pred], observed=[d], valid=[valid],
                      normals=[normals], foreground=foreground)[1]["depth"]

    assert loss(err_fg, foreground=[fg]) > 3 * loss(err_bg, foreground=[fg])
    assert abs(loss(err_fg, foreground=None) - loss(err_bg, foreground=None)) < 1e-7   # option off: alike
    assert isinstance(DDDLoss(), torch.nn.Module) and masked_mean(d, valid) == 2.0


def test_each_view_finds_the_moving_disc_from_its_own_depth(tmp_path):
    _rig_session(tmp_path / "rig", seed=0, frames=10)
    views = [AlignedDataset(tmp_path / "rig" / f"view{k}") for k in range(3)]
    samples = MultiViewSamples(rig_groups(views), foreground=True)
    assert "foreground" not in MultiViewSamples(rig_groups(views))[0]
    ious = []
    for k in range(len(samples)):
        s = samples[k]
        assert s["foreground"].shape == s["depth"].shape
        for v in range(3):
            truth_disc = (views[v].truth(samples.groups[0].rows[k][v]) < 2.0) & (s["valid"][v, 0].numpy() > 0)
            found = s["foreground"][v, 0].numpy() > 0.5
            if truth_disc.sum() > 100:
                ious.append((found & truth_disc).sum() / (found | truth_disc).sum())
    assert len(ious) > 10 and np.median(ious) > 0.8, ious


def test_highpass_option_removes_a_smooth_offset_of_the_correction_but_keeps_a_local_one():
    """A net whose correction is a constant offset (last layer: zero weights, bias 0.5) moves the
    surface by 5 cm without the option and not at all with it; a one-pixel correction survives."""
    from methods.ddd.net import DDDNet

    g = torch.Generator().manual_seed(0)
    depth = 2.0 + 0.01 * torch.rand(1, 1, 32, 40, generator=g)
    mask = torch.ones_like(depth)
    mask[..., 5:8, 10:14] = 0
    out = {}
    for hp in (0.0, 2.0):
        net = DDDNet(width=2, input_scale_m=0.1, highpass_px=hp)
        with torch.no_grad():
            net.out2.conv.weight.zero_()
            net.out2.conv.bias.fill_(0.5)
        with torch.no_grad():
            out[hp] = net(depth * mask, mask)
    m = mask > 0
    assert torch.allclose(out[0.0][m] - depth[m], torch.full_like(depth[m], 0.05), atol=1e-5)
    assert float((out[2.0][m] - depth[m]).abs().max()) < 1e-5
    spike = torch.zeros_like(depth)
    spike[..., 20, 20] = 1.0
    from methods.ddd.warmup import smoothed_input
    hp = spike - smoothed_input(spike, mask, sigma_px=2.0)
    assert float(hp[..., 20, 20]) > 0.9 and abs(float((hp * mask).sum())) < 0.05   # local detail kept, mean ~0
