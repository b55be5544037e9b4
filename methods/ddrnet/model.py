"""DDRNet on metric depth: the training loss of one batch and inference, around :mod:`methods.ddrnet.nets`.

A batch (``methods.nn.data.AlignedSamples``, single frames) holds ``lq_depth`` (the input ``D_in``),
``reference`` (the warped HQ depth: ``D_ref``), ``color`` (the LQ colour image, grey = Rec. 601
luminance in ``[0, 1]``: the ``I`` of the shading loss), ``roi`` (the foreground mask ``W`` of the
paper) and ``camera`` (``fx, fy, cx, cy`` of the crop). Losses are taken over
``W & valid reference & measured input & |D_in - D_ref| < max_ref_diff_m``: like the released
code's ``diff_thres``, the last condition drops pixels where the warped reference sees another
surface than the LQ sensor (occlusions of the warp, mixed pixels), which would otherwise dominate
the L2 terms with metre-sized "errors". See :mod:`methods.ddrnet.losses` for the terms.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import torch
import torch.nn.functional as F

from methods.ddrnet.losses import ALBEDOS, DDRNetLoss, DDRNetWeights
from methods.ddrnet.nets import DDRNet, denormalise_depth, normalise_depth
from methods.nn.distributed import unwrap

LUMA = (0.299, 0.587, 0.114)


@dataclass
class ModelConfig:
    """``width``: denoising net's first width (32 -> 64 -> 128); ``refine_width``: hypercolumn width
    (16 -> 32 -> 64); ``residual_refine``: refined depth = ``D_dn + tanh(.)`` (False: ``tanh(.)``, released);
    ``max_correction_m``: at inference, keep the input depth wherever the output moves it by more than this
    (0: off, the paper; :func:`gate_correction`)."""

    width: int = 32
    refine_width: int = 16
    residual_refine: bool = True
    max_correction_m: float = 0.0

    def __post_init__(self) -> None:
        if self.width < 1 or self.refine_width < 4 or self.max_correction_m < 0:
            raise ValueError(f"model.width must be >= 1, model.refine_width >= 4 and model.max_correction_m >= 0, "
                             f"got {self.width}, {self.refine_width}, {self.max_correction_m}")


@dataclass
class LossConfig(DDRNetWeights):
    """The lambdas of eq. 13-20 (see :class:`methods.ddrnet.losses.DDRNetWeights`), the albedo
    choice (``ratio`` or ``uniform``), ``released_terms`` (drop eq. 12 and 19 as the released code) and
    ``max_ref_diff_m`` (pixels whose reference differs more from the input are left out; 0: keep all),
    ``foreground_only`` (losses inside the foreground mask ``W`` as the paper; false: every pixel with a
    reference, more signal per crop when the foreground is small)."""

    albedo: str = "ratio"
    released_terms: bool = False
    max_ref_diff_m: float = 0.3
    foreground_only: bool = True

    def __post_init__(self) -> None:
        if self.albedo not in ALBEDOS:
            raise ValueError(f"loss.albedo must be one of {', '.join(ALBEDOS)}, got {self.albedo!r}")
        for k in [f.name for f in fields(DDRNetWeights)] + ["max_ref_diff_m"]:
            if getattr(self, k) < 0:
                raise ValueError(f"loss.{k} must be >= 0, got {getattr(self, k)}")

    def module(self) -> DDRNetLoss:
        lambdas = DDRNetWeights(**{f.name: getattr(self, f.name) for f in fields(DDRNetWeights)})
        return DDRNetLoss(weights=lambdas, albedo=self.albedo, released_terms=self.released_terms)


def build(model: ModelConfig, *, refine: bool) -> DDRNet:
    return DDRNet(refine=refine, width=model.width, refine_width=model.refine_width, residual_refine=model.residual_refine)


def grey_of(color: torch.Tensor) -> torch.Tensor:
    """``(B, 3, H, W)`` RGB in ``[0, 1]`` -> ``(B, 1, H, W)`` luminance in ``[0, 1]``."""
    w = torch.tensor(LUMA, dtype=color.dtype, device=color.device).view(1, 3, 1, 1)
    return (color * w).sum(dim=1, keepdim=True)


def fill_holes(depth: torch.Tensor, *, steps: int = 8) -> torch.Tensor:
    """Holes (NaN or <= 0) filled from their measured neighbours: each step fills the hole pixels
    that touch a measured or filled pixel with the mean of those in their 3x3 window (a front moving
    one pixel per step); what is left after ``steps`` gets the image's mean depth. The released code
    feeds the network hole-filled depth too (its ``depth_filled`` input); filled values only steer
    the convolutions near holes, they are never scored."""
    valid = torch.isfinite(depth) & (depth > 0)
    m = valid.to(depth.dtype)
    d = torch.where(valid, depth, torch.zeros_like(depth))
    for _ in range(steps):
        if bool((m > 0).all()):  # nothing left to fill (a frame without holes costs nothing)
            return d
        num = F.avg_pool2d(d * m, 3, stride=1, padding=1)
        den = F.avg_pool2d(m, 3, stride=1, padding=1)
        grow = (m == 0) & (den > 0)
        d = torch.where(grow, num / den.clamp_min(1e-12), d)
        m = torch.where(grow, torch.ones_like(m), m)
    mean = (d * m).sum(dim=(-2, -1), keepdim=True) / m.sum(dim=(-2, -1), keepdim=True).clamp_min(1.0)
    return torch.where(m > 0, d, mean.expand_as(d))


def run_metres(net: DDRNet, depth: torch.Tensor, grey: torch.Tensor | None, *, d_min: float,
               d_max: float) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Depth ``(B, 1, H, W)`` metres (NaN holes, filled by :func:`fill_holes`) and grey ``[0, 1]`` ->
    ``(D_dn, D_dt)`` metres (no holes)."""
    x = normalise_depth(fill_holes(depth), d_min=d_min, d_max=d_max)
    g = None if grey is None else grey * 2.0 - 1.0
    dn, dt = net(x, g)
    back = lambda t: None if t is None else denormalise_depth(t, d_min=d_min, d_max=d_max)  # noqa: E731
    return back(dn), back(dt)


def gate_correction(out: torch.Tensor, depth: torch.Tensor, *, max_m: float) -> torch.Tensor:
    """``out`` where ``|out - depth| <= max_m`` (metres) or where ``depth`` is a hole (NaN), else ``depth``;
    ``max_m = 0``: ``out`` unchanged. Shapes ``(B, 1, H, W)``.

    Not in the paper (an inference option, ``model.max_correction_m``): the training loss leaves out every
    pixel whose reference differs from the input by more than ``loss.max_ref_diff_m`` (occlusions of the
    warp, silhouettes), so the nets never learn a large correction, and at silhouettes they make them
    anyway (measured: the ``tiny`` DDRNet's MSE inside the people worse than the raw depth's, from pixels
    within 3 px of a depth edge). A denoiser's correction is a few noise sigmas; beyond the gate the
    input is kept.
    """
    if not max_m:
        return out
    return torch.where((out - depth).abs() > max_m, depth, out)


def _frame(batch: dict, key: str) -> torch.Tensor:
    t = batch[key]
    return t[:, 0] if t.ndim == 5 else t  # (B, T=1, C, H, W) -> (B, C, H, W)


def batch_loss(loss_cfg: LossConfig, *, d_min: float, d_max: float):
    """``loss(net, batch) -> (scalar, {term: value})`` for :class:`methods.nn.trainer.FitJob` (eq. 20)."""
    module = loss_cfg.module()

    def loss(net: DDRNet, batch: dict) -> torch.Tensor:
        depth, ref = _frame(batch, "lq_depth"), _frame(batch, "reference")
        grey = grey_of(_frame(batch, "color"))
        mask = torch.isfinite(ref) & torch.isfinite(depth)
        if loss_cfg.foreground_only:
            mask = mask & (_frame(batch, "roi") > 0.5)
        if loss_cfg.max_ref_diff_m > 0:
            mask = mask & ((depth - ref).abs() < loss_cfg.max_ref_diff_m)
        dn, dt = run_metres(net, depth, grey if unwrap(net).refine is not None else None, d_min=d_min, d_max=d_max)
        return module(d_dn=dn, d_dt=dt, ref=torch.nan_to_num(ref, nan=0.0), mask=mask,
                      K=batch["camera"].to(depth.dtype), grey=grey)

    return loss

