"""``ddd``: DDD's partial-convolution autoencoder behind the :class:`methods.base.Denoiser` interface.

Trained on four simultaneous views (``depthbench methods train ddd``), it denoises one depth map at
a time: depth in, depth out (metres). See :class:`methods.nn.learned.LearnedDenoiser` for holes, the
leakage guard and weight errors.
"""
from __future__ import annotations

from methods.nn.learned import LearnedDenoiser


class DDD(LearnedDenoiser):
    """Self-supervised deep depth denoising (Sterzentsenko et al. 2019)."""

    name = "ddd"
    version = "1"
    description = "DDD partial-convolution autoencoder (Sterzentsenko et al. 2019), self-supervised on multi-view data; needs weights"
    trained_as = ("ddd",)
    not_in_paper = ("warmup.steps", "model.input_scale_m", "model.highpass_px", "loss.foreground_weight")

    @property
    def schema(self):
        from methods.ddd.train import DDDConfig

        return DDDConfig

    def build(self, config):
        from methods.ddd.model import build

        return build(config.model)

    def _run(self, depth, color):
        from methods.ddd.model import denoise_metres

        return denoise_metres(self.runtime["net"], depth)
