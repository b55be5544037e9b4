"""The networks: each overfits one batch (loss down 10x) and every parameter gets a gradient from
its full training loss (DDRNet eq. 20, DDD eq. 22 through the splatting renderer)."""
from __future__ import annotations

import numpy as np
import torch

from methods.ddd.losses import DDDLoss
from methods.ddd.model import LossConfig as DDDLossConfig, multiview_loss
from methods.ddd.net import DDDNet
from methods.ddrnet.losses import DDRNetLoss, reconstruction_loss
from methods.ddrnet.nets import DDRNet, denormalise_depth, normalise_depth

K = torch.tensor([[30.0, 30.0, 15.5, 11.5]])


def _scene(seed=0, b=2, h=24, w=32):
    g = torch.Generator().manual_seed(seed)
    v, u = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij")
    ref = 1.5 + 0.01 * u + 0.3 * torch.exp(-((u - 16) ** 2 + (v - 12) ** 2) / 40.0)
    ref = ref.expand(b, 1, h, w).clone()
    noisy = ref + 0.02 * torch.randn(b, 1, h, w, generator=g)
    grey = (0.3 + 0.5 * torch.rand(b, 1, h, w, generator=g)).clamp(0, 1)
    return ref, noisy, grey


def _overfit(net, loss_fn, steps=250, lr=3e-3):
    """Adam with a linearly decaying step; returns the loss before and after."""
    torch.manual_seed(0)
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda i: 1 - i / steps)
    first = None
    for _ in range(steps):
        opt.zero_grad()
        loss = loss_fn()
        loss.backward()
        opt.step()
        sched.step()
        first = float(loss.detach()) if first is None else first
    with torch.no_grad():
        return first, float(loss_fn())


def _all_params_have_gradients(net):
    missing = [n for n, p in net.named_parameters() if p.grad is None or not torch.isfinite(p.grad).all() or p.grad.abs().sum() == 0]
    assert not missing, missing


def test_ddrnet_overfits_one_batch_and_every_parameter_learns_from_eq20():
    torch.manual_seed(0)
    ref, noisy, grey = _scene(b=1, h=16, w=16)
    mask = torch.ones_like(ref, dtype=torch.bool)
    for refine in (False, True):
        net = DDRNet(refine=refine, width=8, refine_width=8)
        x = normalise_depth(noisy, d_min=0.5, d_max=3.0)

        def rec():
            dn, dt = net(x, grey * 2 - 1)
            return reconstruction_loss(denormalise_depth(dn if dt is None else dt, d_min=0.5, d_max=3.0), ref, mask)

        first, last = _overfit(net, rec)
        assert last < first / 10, (refine, first, last)
        net = DDRNet(refine=refine, width=8, refine_width=8)
        ref2, noisy2, grey2 = _scene()
        dn, dt = net(normalise_depth(noisy2, d_min=0.5, d_max=3.0), grey2 * 2 - 1)
        back = lambda t: None if t is None else denormalise_depth(t, d_min=0.5, d_max=3.0)  # noqa: E731
        total, terms = DDRNetLoss()(d_dn=back(dn), d_dt=back(dt), ref=ref2, mask=torch.ones_like(ref2, dtype=torch.bool),
                                    K=K, grey=grey2)
        total.backward()
        _all_params_have_gradients(net)


def _three_views(b=1, h=24, w=32):
    """A textured fronto-parallel wall at 2 m seen by three cameras shifted along x (known rig)."""
    ref, noisy, _ = _scene(1, b=b * 3, h=h, w=w)
    depth = torch.full((b, 3, 1, h, w), 2.0) + 0.02 * torch.randn(b, 3, 1, h, w)
    color = torch.rand(b, 3, 3, h, w)
    T = torch.eye(4).repeat(b, 3, 1, 1)
    T[:, 1, 0, 3], T[:, 2, 0, 3] = 0.05, -0.05
    return {"depth": depth, "valid": torch.ones(b, 3, 1, h, w), "color": color, "camera": K.expand(b, 3, 4).clone(),
            "T_rig": T}


def test_ddd_overfits_one_batch_and_every_parameter_learns_from_eq22():
    torch.manual_seed(0)
    ref, noisy, _ = _scene(2, b=1, h=16, w=16)
    mask = torch.ones_like(ref)
    net = DDDNet(width=4)
    first, last = _overfit(net, lambda: (net(noisy, mask) - ref).abs().mean())
    assert last < first / 10, (first, last)
    net = DDDNet(width=4)
    cfg = DDDLossConfig(z_max_m=3.0)
    total, terms = multiview_loss(net, _three_views(), cfg, cfg.module())
    assert set(terms) == {"photometric", "depth", "surface"} and all(np.isfinite(list(terms.values())))
    total.backward()
    _all_params_have_gradients(net)
    assert isinstance(cfg.module(), DDDLoss)
