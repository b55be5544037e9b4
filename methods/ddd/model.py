"""DDD's multi-view training step (seed Fig. 7, eq. 21-27) and single-view inference.

Training: the shared autoencoder denoises each of the ``V`` views of a sample; for every target
view ``t`` the other views' colours are splatted into ``t`` with their *predicted* depths
(:func:`methods.ddd.splatting.render_view`, eq. 21) and compared with ``t``'s own colour over the
pixels where ``t`` has a measurement and something landed (eq. 23-25); BerHu ties each prediction to
its own measurement (eq. 26) and the surface prior smooths its normals (eq. 27). Inference: one
depth map in, one out.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from methods.ddd.losses import DDDLoss, DDDWeights
from methods.ddd.net import DDDNet
from methods.ddd.splatting import render_view
from methods.nn.geometry import normals_from_depth


@dataclass
class ModelConfig:
    """``width``: first channel step (8 -> 16 -> 32 -> 64 -> 128); ``residual``: add the input depth;
    ``input_scale_m``: centred input coding (0: metres, as released; see :mod:`methods.ddd.net`);
    ``highpass_px``: keep only the correction's high frequencies (0: off, the paper; :mod:`methods.ddd.net`)."""

    width: int = 8
    residual: bool = True
    input_scale_m: float = 0.0
    highpass_px: float = 0.0

    def __post_init__(self) -> None:
        if self.width < 1 or min(self.input_scale_m, self.highpass_px) < 0 or \
                ((self.input_scale_m or self.highpass_px) and not self.residual):
            raise ValueError(f"model.width must be >= 1, model.input_scale_m and model.highpass_px >= 0 (with "
                             f"residual = true), got {self.width}, {self.input_scale_m}, {self.highpass_px}")


@dataclass
class LossConfig:
    """Eq. 22-27: weights (sum 1), ``alpha``, Charbonnier ``gamma``, BerHu ``c_over`` (``valid``:
    the paper; ``all``: the released code), SSIM window radius (0: 11x11 Gaussian; released: 2),
    splatting ``z_max_m`` of the weight ``exp(-2 z / z_max)``; ``foreground_weight`` (0: the paper, every
    pixel alike; ``w`` in (0, 1]: each view's own foreground, :mod:`methods.ddd.multiview`, carries the
    share ``w`` of every mean of eq. 23-27, :func:`methods.ddd.losses.split_mean`)."""

    photometric: float = 0.85
    depth: float = 0.1
    surface: float = 0.05
    alpha: float = 0.85
    gamma: float = 1e-3
    c_over: str = "valid"
    ssim_radius: int = 0
    z_max_m: float = 6.0
    foreground_weight: float = 0.0

    def __post_init__(self) -> None:
        if not 0 <= self.foreground_weight <= 1:
            raise ValueError(f"loss.foreground_weight must be in [0, 1], got {self.foreground_weight}")
        if self.c_over not in ("valid", "all"):
            raise ValueError(f"loss.c_over must be 'valid' or 'all', got {self.c_over!r}")
        if min(self.photometric, self.depth, self.surface) < 0 or not 0 <= self.alpha <= 1 or self.z_max_m <= 0:
            raise ValueError("loss weights must be >= 0, alpha in [0, 1] and z_max_m > 0")

    def module(self) -> DDDLoss:
        w = DDDWeights(photometric=self.photometric, depth=self.depth, surface=self.surface, alpha=self.alpha)
        return DDDLoss(weights=w, gamma=self.gamma, c_over=self.c_over, ssim_radius=self.ssim_radius or None,
                       foreground_weight=self.foreground_weight)


def build(model: ModelConfig) -> DDDNet:
    return DDDNet(width=model.width, residual=model.residual, input_scale_m=model.input_scale_m,
                  highpass_px=model.highpass_px)


def multiview_loss(net: DDDNet, batch: dict, cfg: LossConfig, module: DDDLoss) -> tuple[torch.Tensor, dict]:
    """Eq. 22 for a batch of ``V``-view samples (keys of :class:`methods.ddd.multiview.MultiViewSamples`)."""
    depth, valid, color, cam, T_rig = batch["depth"], batch["valid"] > 0.5, batch["color"], batch["camera"], batch["T_rig"]
    b, v, _, h, w = depth.shape
    pred = net(depth.flatten(0, 1), valid.flatten(0, 1).to(depth.dtype)).view(b, v, 1, h, w)
    rendered, targets, photo_masks, normals = [], [], [], []
    for t in range(v):
        T_t_inv = torch.linalg.inv(T_rig[:, t])
        sources = [dict(depth=pred[:, s], valid=valid[:, s], color=color[:, s], K=cam[:, s], T_ts=T_t_inv @ T_rig[:, s])
                   for s in range(v) if s != t]
        img, _, acc = render_view(sources, cam[:, t], (h, w), z_max=cfg.z_max_m)
        rendered.append(img)
        targets.append(color[:, t])
        photo_masks.append(valid[:, t] & (acc > 1e-6))
        normals.append(normals_from_depth(pred[:, t], cam[:, t], valid[:, t]))
    fg = batch.get("foreground")
    return module(rendered=rendered, targets=targets, photo_masks=photo_masks, preds=[pred[:, s] for s in range(v)],
                  observed=[depth[:, s] for s in range(v)], valid=[valid[:, s] for s in range(v)], normals=normals,
                  foreground=None if fg is None else [fg[:, s] > 0.5 for s in range(v)])


def batch_loss(cfg: LossConfig):
    """``loss(net, batch) -> (scalar, {term: value})`` for :class:`methods.nn.trainer.FitJob` (eq. 22)."""
    module = cfg.module()

    def loss(net, batch: dict):
        return multiview_loss(net, batch, cfg, module)

    return loss


@torch.no_grad()
def denoise_metres(net: DDDNet, depth: torch.Tensor) -> torch.Tensor:
    """Inference: depth ``(B, 1, H, W)`` metres with NaN holes -> denoised depth at every pixel (the
    partial convolutions' estimate in holes; callers keep holes as holes unless they want it)."""
    valid = torch.isfinite(depth) & (depth > 0)
    return net(torch.where(valid, depth, torch.zeros_like(depth)), valid.to(depth.dtype))
