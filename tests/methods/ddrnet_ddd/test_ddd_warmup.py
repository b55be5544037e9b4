"""DDD's warm start (methods/ddd/warmup.py) and the centred input coding of its network (methods/ddd/net.py)."""
from __future__ import annotations

import numpy as np
import torch

from methods.ddd.net import DDDNet
from methods.ddd.warmup import WarmupConfig, smoothed_input, warm_start, warmup_loss


def test_smoothed_input_is_the_hole_aware_gaussian_mean_of_a_direct_loop():
    rng = np.random.default_rng(0)
    d = rng.uniform(1.0, 3.0, (9, 11))
    m = rng.random((9, 11)) > 0.3
    m[:4, :4] = False   # a hole wider than the kernel: no measured pixel within reach of (0, 0)
    sigma, r = 0.8, 2
    out = smoothed_input(torch.tensor(d * m)[None, None], torch.tensor(m, dtype=torch.float64)[None, None],
                         sigma_px=sigma)[0, 0].numpy()
    for y in range(9):
        for x in range(11):
            num = den = 0.0
            for dy in range(-r, r + 1):
                for dx in range(-r, r + 1):
                    yy, xx = y + dy, x + dx
                    if 0 <= yy < 9 and 0 <= xx < 11 and m[yy, xx]:
                        g = np.exp(-(dy * dy + dx * dx) / (2 * sigma * sigma))
                        num, den = num + g * d[yy, xx], den + g
            assert abs(out[y, x] - (num / den if den else 0.0)) < 1e-9


def test_warm_start_brings_the_network_towards_the_smoothed_input():
    torch.manual_seed(0)
    rng = np.random.default_rng(1)
    views = []
    for _ in range(3):
        d = torch.from_numpy((2.0 + 0.3 * np.sin(np.arange(40) / 6.0)[None, :] + rng.normal(0, 0.03, (32, 40)))
                             .astype(np.float32))[None]
        m = torch.from_numpy(rng.random((1, 32, 40)) > 0.05).float()
        views.append((d * m, m))
    net = DDDNet(width=2, input_scale_m=0.1)
    d, m = torch.stack([v[0] for v in views]), torch.stack([v[1] for v in views])
    before = float(warmup_loss(net, d, m, sigma_px=1.0).detach())   # the near-identity start: about the noise
    warm_start(net, views, WarmupConfig(steps=60, batch=4, crop=24, lr=1e-2))
    after = float(warmup_loss(net, d, m, sigma_px=1.0).detach())
    assert after < 0.7 * before, (before, after)


def test_centred_input_coding_makes_the_correction_independent_of_a_depth_offset():
    """With input_scale_m the network sees (D - mean) / s: adding a constant to the depth adds it to the output."""
    torch.manual_seed(0)
    net = DDDNet(width=2, input_scale_m=0.1)
    with torch.no_grad():
        net.out2.conv.weight.normal_(0, 0.1)   # a visible correction, not the near-identity start
    d = 2.0 + 0.05 * torch.randn(1, 1, 24, 32, dtype=torch.float32)
    m = (torch.rand(1, 1, 24, 32) > 0.1).float()
    with torch.no_grad():
        a, b = net(d * m, m), net((d + 0.7) * m, m)
    assert float(((a - d * m) * m).abs().max()) > 1e-3           # it does change the depth
    assert torch.allclose((b - a) * m, 0.7 * m, atol=1e-4)      # by the same amount at any offset
    plain = DDDNet(width=2)
    with torch.no_grad():
        plain.out2.conv.weight.normal_(0, 0.1)
    with torch.no_grad():
        assert not torch.allclose((plain((d + 0.7) * m, m) - plain(d * m, m)) * m, 0.7 * m, atol=1e-4)
