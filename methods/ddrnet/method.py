"""``ddrnet`` and ``ddrnet_refine``: DDRNet behind the :class:`methods.base.Denoiser` interface.

``ddrnet`` runs the denoising net alone (how DDD's comparison ran DDRNet); ``ddrnet_refine`` the
denoising and refinement nets (the paper's pipeline), which needs the LQ colour image. Weights
come from ``depthbench methods train ddrnet`` (``--param weights=RUN/ddrnet.safetensors``); the
depth normalisation and the correction gate (``model.max_correction_m``) are those of the config the
weights were trained with (see :class:`methods.nn.learned.LearnedDenoiser` for holes, the leakage
guard and weight errors).
"""
from __future__ import annotations

from methods.nn.learned import LearnedDenoiser


class _DDRNetBase(LearnedDenoiser):
    version = "1"
    refine = False
    not_in_paper = ("model.max_correction_m",)

    @property
    def schema(self):
        from methods.ddrnet.train import DDRNetConfig

        return DDRNetConfig

    def build(self, config):
        from methods.ddrnet.model import build

        return build(config.model, refine=self.refine)

    def _run(self, depth, color):
        from methods.ddrnet.model import gate_correction, grey_of, run_metres

        data = self.config.data
        dn, dt = run_metres(self.runtime["net"], depth, grey_of(color) if self.refine else None,
                            d_min=data.depth_min_m, d_max=data.depth_max_m)
        return gate_correction(dt if self.refine else dn, depth, max_m=self.config.model.max_correction_m)


class DDRNetDenoise(_DDRNetBase):
    """DDRNet's denoising net alone (Fig. 5)."""

    name = "ddrnet"
    description = "DDRNet denoising net (Yan et al. 2018), trained on aligned LQ/HQ data; needs weights"
    trained_as = ("ddrnet",)


class DDRNetRefine(_DDRNetBase):
    """DDRNet's denoising and refinement nets (Fig. 4-6)."""

    name = "ddrnet_refine"
    description = "DDRNet denoise + shading-based refinement (Yan et al. 2018); needs colour and weights"
    trained_as = ("ddrnet_refine",)
    uses_color = True
    refine = True
