"""DDRNet's inference gate (``model.max_correction_m``): the input is kept where a net moves it too far."""
from __future__ import annotations

import numpy as np
import torch

from bench.report import _not_in_paper
from methods.ddrnet.model import build, gate_correction
from methods.ddrnet.train import DDRNetConfig
from methods.nn.checkpoint import save_tensors
from methods.nn.config import from_dict, to_dict
from methods.registry import get


def test_gate_keeps_the_input_beyond_the_limit_and_the_output_elsewhere_against_a_direct_loop():
    rng = np.random.default_rng(0)
    depth = rng.uniform(1.0, 3.0, (2, 1, 6, 7)).astype(np.float32)
    depth[0, 0, 1, 2] = np.nan
    out = depth + rng.normal(0.0, 0.05, depth.shape).astype(np.float32)
    out[0, 0, 1, 2] = 2.0
    got = gate_correction(torch.from_numpy(out), torch.from_numpy(depth), max_m=0.04).numpy()
    for idx in np.ndindex(depth.shape):
        d, o = depth[idx], out[idx]
        want = o if np.isnan(d) or abs(o - d) <= 0.04 else d
        assert got[idx] == want, idx
    assert (got == depth).sum() > 5 and np.isfinite(got).all()   # both branches taken
    assert torch.equal(gate_correction(torch.from_numpy(out), torch.from_numpy(depth), max_m=0.0), torch.from_numpy(out))


def _weights(path, cfg, net):
    save_tensors(path, {f"net/{k}": v for k, v in net.state_dict().items()}, kind="weights",
                 meta={"method": "ddrnet", "config": to_dict(cfg), "training": {"datasets": []}})
    return str(path)


def test_ddrnet_method_applies_the_gate_of_its_weights_config(tmp_path):
    torch.manual_seed(0)
    plain = from_dict(DDRNetConfig, {"model": {"width": 4, "refine_width": 4}}, where="test")
    net = build(plain.model, refine=False)
    with torch.no_grad():   # a net far from the identity: corrections of centimetres to decimetres
        for p in net.parameters():
            p.add_(0.3 * torch.randn_like(p))
    rng = np.random.default_rng(1)
    depth = rng.uniform(1.0, 3.0, (24, 32)).astype(np.float32)
    depth[3:6, 4:8] = np.nan
    plain_method = get("ddrnet", weights=_weights(tmp_path / "a.safetensors", plain, net))
    free = plain_method.denoise(depth)
    ok = np.isfinite(depth)
    limit = float(np.median(np.abs(free - depth)[ok]))   # half the pixels beyond the gate
    gated = from_dict(DDRNetConfig, {"model": {"width": 4, "refine_width": 4, "max_correction_m": limit}}, where="test")
    gated_method = get("ddrnet", weights=_weights(tmp_path / "b.safetensors", gated, net))
    out = gated_method.denoise(depth)
    big = ok & (np.abs(free - depth) > limit)
    assert 0 < big.sum() < ok.sum()
    assert np.array_equal(out[big], depth[big]) and np.array_equal(out[ok & ~big], free[ok & ~big])
    assert np.isnan(out[~ok]).all()
    # the leaderboard's config column names the option (not in the paper) only where it is on
    assert "not_in_paper" not in plain_method.provenance()
    assert gated_method.provenance()["not_in_paper"] == [f"model.max_correction_m = {limit!r}"]
    assert "not in the paper: `model.max_correction_m = " in _not_in_paper(gated_method.provenance())
