"""The methods behind the Denoiser interface: weights files in, depth out; bad weights are one line."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from methods.ddd.model import build as build_ddd
from methods.ddd.train import DDDConfig
from methods.ddrnet.model import build as build_ddrnet
from methods.ddrnet.train import DDRNetConfig
from methods.errors import MethodError
from methods.nn.checkpoint import save_tensors
from methods.nn.config import from_dict, to_dict
from methods.registry import get


def _weights(path, method, cfg, net):
    save_tensors(path, {f"net/{k}": v for k, v in net.state_dict().items()}, kind="weights",
                 meta={"method": method, "config": to_dict(cfg), "training": {"datasets": []}})
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp("weights")
    torch.manual_seed(0)
    rc = from_dict(DDRNetConfig, {"model": {"width": 4, "refine_width": 4}}, where="test")
    dc = from_dict(DDDConfig, {"model": {"width": 2}}, where="test")
    return {"ddrnet": _weights(root / "ddrnet.safetensors", "ddrnet", rc, build_ddrnet(rc.model, refine=False)),
            "ddrnet_refine": _weights(root / "ddrnet_refine.safetensors", "ddrnet_refine", rc,
                                      build_ddrnet(rc.model, refine=True)),
            "ddd": _weights(root / "ddd.safetensors", "ddd", dc, build_ddd(dc.model))}


def test_methods_denoise_keep_holes_and_are_near_the_identity_untrained(files):
    rng = np.random.default_rng(0)
    depth = rng.uniform(1.0, 3.0, (30, 41)).astype(np.float32)
    depth[5:9, 10:14] = np.nan
    color = rng.integers(0, 255, (30, 41, 3), dtype=np.uint8)
    for name, path in files.items():
        m = get(name, weights=str(path))
        out = m.denoise(depth, color)
        assert out.shape == depth.shape and out.dtype == np.float32
        assert np.isnan(out[5:9, 10:14]).all() and np.isfinite(out[np.isfinite(depth)]).all()
        assert np.nanmax(np.abs(out - depth)) < 0.1, name  # small last layers: an untrained net is near the identity
        filled = get(name, weights=str(path), fill_holes=True).denoise(depth, color)
        assert np.isfinite(filled).all()
        assert "sha256:" in m.key and m.provenance()["trained_method"] == name


def test_corrupt_foreign_or_mismatched_weights_are_one_line_errors(files, tmp_path):
    bad = tmp_path / "bad.safetensors"
    data = files["ddd"].read_bytes()
    bad.write_bytes(data[: len(data) // 3])
    pickle = tmp_path / "pickle.safetensors"
    torch.save({"w": torch.zeros(2)}, pickle)
    for name in ("ddrnet", "ddrnet_refine", "ddd"):
        for path in (bad, pickle):
            with pytest.raises(MethodError) as e:
                get(name, weights=str(path))
            assert "\n" not in str(e.value) and str(path) in str(e.value)
    with pytest.raises(MethodError, match="weights of 'ddrnet_refine'"):
        get("ddrnet", weights=str(files["ddrnet_refine"]))
    with pytest.raises(MethodError, match="weights of 'ddd'"):
        get("ddrnet_refine", weights=str(files["ddd"]))
