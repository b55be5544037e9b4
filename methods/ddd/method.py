"""``ddd``: DDD's partial-convolution autoencoder behind the :class:`methods.base.Denoiser` interface.

Trained on four simultaneous views (``depthbench methods train ddd``), it denoises one depth map
at a time: depth in, depth out (metres; pixels without a measurement stay NaN).
"""
from __future__ import annotations

import numpy as np

from methods.base import Denoiser


class DDD(Denoiser):
    """Self-supervised deep depth denoising (Sterzentsenko et al. 2019)."""

    name = "ddd"
    version = "1"
    description = "DDD partial-convolution autoencoder (Sterzentsenko et al. 2019), self-supervised on multi-view data"
    learned = True
    weights_param = "weights"
    defaults = {"weights": None}
    param_help = {"weights": "weights file from 'depthbench methods train ddd' (RUN/ddd.safetensors)"}

    def check_params(self, params):
        from methods.nn.learned import read_weights

        read_weights(self.weights_path, method=self.name)

    def prepare(self) -> None:
        from methods.ddd.model import build
        from methods.ddd.train import DDDConfig
        from methods.nn.learned import load_network

        loaded = load_network(self.weights_path, method=self.name, schema=DDDConfig, sha256=self.weights_sha256,
                              build=lambda cfg: build(cfg.model))
        self.runtime["net"] = loaded.net

    def provenance(self) -> dict:
        from methods.nn.learned import read_weights

        meta = read_weights(self.weights_path, method=self.name).meta
        return {"training": meta.get("training"), "config_file": meta.get("config_file"),
                "git_revision": meta.get("git_revision")}

    def _denoise(self, depth, color, camera):
        import torch

        from methods.ddd.model import denoise_metres

        if not self.runtime:
            self.prepare()
        out = denoise_metres(self.runtime["net"], torch.from_numpy(depth)[None, None])
        return out[0, 0].numpy().astype(np.float32)
