"""``ddrnet`` and ``ddrnet_refine``: DDRNet behind the :class:`methods.base.Denoiser` interface.

``ddrnet`` runs the denoising net alone (how DDD's comparison ran DDRNet); ``ddrnet_refine`` the
denoising and refinement nets (the paper's pipeline), which needs the LQ colour image. Weights
come from ``depthbench methods train ddrnet`` (``--param weights=RUN/ddrnet.safetensors``); the
depth normalisation is the one the weights were trained with. Pixels without an input measurement
stay NaN (the nets fill them, but no method here claims hole filling).
"""
from __future__ import annotations

import numpy as np

from methods.base import Denoiser


class _DDRNetBase(Denoiser):
    version = "1"
    learned = True
    uses_camera = False
    weights_param = "weights"
    defaults = {"weights": None}
    param_help = {"weights": "weights file from 'depthbench methods train ddrnet' (RUN/<method>.safetensors)"}
    refine = False

    def check_params(self, params):
        from methods.nn.learned import read_weights

        read_weights(self.weights_path, method=self.name)  # a corrupt or foreign file fails here, in one line

    def prepare(self) -> None:
        import torch

        from methods.ddrnet.model import build
        from methods.ddrnet.train import DDRNetConfig
        from methods.nn.learned import load_network

        torch.set_grad_enabled(False)
        loaded = load_network(self.weights_path, method=self.name, schema=DDRNetConfig, sha256=self.weights_sha256,
                              build=lambda cfg: build(cfg.model, refine=self.refine))
        self.runtime.update(net=loaded.net, data=loaded.config.data)

    def provenance(self) -> dict:
        from methods.nn.learned import read_weights

        meta = read_weights(self.weights_path, method=self.name).meta
        return {"training": meta.get("training"), "config_file": meta.get("config_file"),
                "git_revision": meta.get("git_revision")}

    def _denoise(self, depth, color, camera):
        import torch

        from methods.ddrnet.model import grey_of, run_metres

        if not self.runtime:
            self.prepare()
        data = self.runtime["data"]
        d = torch.from_numpy(depth)[None, None]
        grey = None
        if self.refine:
            c = color.astype(np.float32) / (65535.0 if color.dtype == np.uint16 else 255.0 if color.dtype == np.uint8 else 1.0)
            c = torch.from_numpy(np.ascontiguousarray(c if c.ndim == 3 else np.repeat(c[..., None], 3, axis=2))).permute(2, 0, 1)[None]
            grey = grey_of(c)
        with torch.no_grad():
            dn, dt = run_metres(self.runtime["net"], d, grey, d_min=data.depth_min_m, d_max=data.depth_max_m)
        out = (dt if self.refine else dn)[0, 0].numpy()
        return np.where(np.isfinite(depth), out, np.nan).astype(np.float32)


class DDRNetDenoise(_DDRNetBase):
    """DDRNet's denoising net alone (Fig. 5)."""

    name = "ddrnet"
    description = "DDRNet denoising net (Yan et al. 2018), trained on aligned LQ/HQ data"


class DDRNetRefine(_DDRNetBase):
    """DDRNet's denoising and refinement nets (Fig. 4-6)."""

    name = "ddrnet_refine"
    description = "DDRNet denoise + shading-based refinement (Yan et al. 2018), needs colour"
    uses_color = True
    refine = True
