"""DDD's losses, eq. 22-27 of the seed report, as pure torch functions plus an ``nn.Module``.

Shapes: colour ``(B, 3, H, W)`` in ``[0, 1]``, depth ``(B, 1, H, W)`` metres, masks ``(B, 1, H, W)``
bool. Sums over pixels in the paper are means over the mask here (weights independent of size).

* eq. 24 ``L_col = sum_p rho(M(p) ||I(p) - I^(p)||_1)``, Charbonnier ``rho(x) = sqrt(x^2 + gamma^2)``
  (we subtract ``gamma`` so that ``rho(0) = 0``; gradients are unchanged). ``gamma`` is "about 0" in
  the paper: default ``1e-3``; the released code uses ``gamma^2 = 0.2``.
* eq. 25 ``L_str = 0.5 sum_p phi(M(p) (1 - SSIM(I, I^)(p)))``, Tukey's biweight
  ``phi(x) = c^2/6 (1 - (1 - (x/c)^2)^3)`` for ``|x| <= c``, else ``c^2/6`` (``c = 2.2``, released);
  SSIM per channel (:func:`methods.nn.ssim.ssim_map`, Gaussian window, sigma 1.5), averaged over
  channels, on the masked images.
* eq. 23 ``L_ph = (1 - alpha) L_col + alpha L_str``, ``alpha = 0.85``.
* eq. 26 BerHu of ``r = M (D - D~)``: ``|r|`` for ``|r| <= c``, ``(r^2 + c^2) / (2c)`` above, with
  ``c = 0.2 max |r|`` over the **valid** pixels of the batch (the seed's "20 % of the maximum per
  batch residual"); ``c_over="all"`` takes the maximum over every pixel, invalid ones included, as
  the released code does (there the prediction at holes inflates ``c``).
* eq. 27 ``L_surface = 1 - sum_p sum_{p' in Theta_p} |<n(p), n(p')>| M(p) / G(Theta_p)``: per valid
  pixel the mean absolute cosine between its normal and those of its valid 8 neighbours, averaged
  over valid pixels with at least one valid neighbour, subtracted from 1. Normals from four
  neighbours (:mod:`methods.nn.geometry`).
* eq. 22 ``L = l1 L_ph + l2 L_depth + l3 L_surface``, ``(0.85, 0.1, 0.05)``.

Foreground weighting (an option, not in the paper; off by default): with a foreground mask ``F`` per
view and a share ``w`` in ``(0, 1]``, every per-pixel mean above becomes
``w mean_{mask & F} + (1 - w) mean_{mask & ~F}`` (:func:`split_mean`; the plain mean where the batch
has no foreground or no background pixel). In the paper every pixel counts the same, so a scene whose
people cover a few percent of the frame trains a filter for its walls and floor; the released code
instead drops every pixel beyond a depth threshold (3 m) from the masks, which keeps the people of
its capture space (``max_depth_m`` in :mod:`methods.ddd.model`).
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn as nn
import torch.nn.functional as F

from methods.nn.ssim import ssim_map

TUKEY_C = 2.2


def masked_mean(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    m = mask.to(x.dtype).expand_as(x)
    return (x * m).sum() / m.sum().clamp_min(1.0)


def split_mean(x: torch.Tensor, mask: torch.Tensor, foreground: torch.Tensor | None = None, *,
               weight: float = 0.0) -> torch.Tensor:
    """``weight * mean(x | mask & foreground) + (1 - weight) * mean(x | mask & ~foreground)``; the
    plain :func:`masked_mean` when ``foreground`` is None, ``weight`` is 0, or either part is empty."""
    if foreground is None or weight == 0.0:
        return masked_mean(x, mask)
    fg = mask & foreground
    bg = mask & ~foreground
    if not bool(fg.any()) or not bool(bg.any()):
        return masked_mean(x, mask)
    return weight * masked_mean(x, fg) + (1.0 - weight) * masked_mean(x, bg)


def charbonnier(x: torch.Tensor, *, gamma: float = 1e-3) -> torch.Tensor:
    """``sqrt(x^2 + gamma^2) - gamma``."""
    return torch.sqrt(x * x + gamma * gamma) - gamma


def tukey(x: torch.Tensor, *, c: float = TUKEY_C) -> torch.Tensor:
    """Tukey's biweight penalty: ``c^2/6 (1 - (1 - (x/c)^2)^3)`` inside ``|x| <= c``, ``c^2/6`` outside."""
    inner = c * c / 6.0 * (1.0 - (1.0 - (x / c) ** 2) ** 3)
    return torch.where(x.abs() <= c, inner, torch.full_like(x, c * c / 6.0))


def photometric_loss(rendered: torch.Tensor, target: torch.Tensor, mask: torch.Tensor, *, alpha: float = 0.85,
                     gamma: float = 1e-3, ssim_radius: int | None = None, foreground: torch.Tensor | None = None,
                     foreground_weight: float = 0.0) -> tuple[torch.Tensor, dict]:
    """Eq. 23-25 over ``mask`` (:func:`split_mean` with ``foreground``); returns ``(L_ph, {"col": .., "str": ..})``."""
    m = mask.to(target.dtype)
    t, r = target * m, rendered * m
    fw = dict(foreground=foreground, weight=foreground_weight)
    col = split_mean(charbonnier((t - r).abs().sum(dim=1, keepdim=True), gamma=gamma), mask, **fw)
    s = ssim_map(r, t, radius=ssim_radius).mean(dim=1, keepdim=True)
    struct = 0.5 * split_mean(tukey(1.0 - s), mask, **fw)
    return (1 - alpha) * col + alpha * struct, {"col": col, "str": struct}


def berhu_threshold(r: torch.Tensor, mask: torch.Tensor, *, over: str = "valid") -> torch.Tensor:
    """``c = 0.2 max |r|`` over ``mask`` (``over="valid"``) or over every pixel (``"all"``); no gradient."""
    a = r.detach().abs()
    if over == "valid":
        a = torch.where(mask, a, torch.zeros_like(a))
    elif over != "all":
        raise ValueError(f"over must be 'valid' or 'all', got {over!r}")
    return (0.2 * a.max()).clamp_min(1e-9)


def berhu(r: torch.Tensor, c: torch.Tensor | float) -> torch.Tensor:
    """Eq. 26 per element: ``|r|`` where ``|r| <= c``, ``(r^2 + c^2) / (2 c)`` elsewhere."""
    a = r.abs()
    return torch.where(a <= c, a, (r * r + c * c) / (2 * c))


def depth_prior_loss(pred: torch.Tensor, observed: torch.Tensor, mask: torch.Tensor, *, c_over: str = "valid",
                     foreground: torch.Tensor | None = None, foreground_weight: float = 0.0) -> torch.Tensor:
    """Eq. 26 averaged over ``mask`` (:func:`split_mean`): BerHu of ``M (D - D~)`` with the batch threshold."""
    r = torch.where(mask, observed - pred, torch.zeros_like(pred)) if c_over == "valid" else \
        observed * mask.to(pred.dtype) - pred
    return split_mean(berhu(r, berhu_threshold(r, mask, over=c_over)), mask, foreground, weight=foreground_weight)


_N8 = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)]


def surface_prior_loss(normals: torch.Tensor, valid: torch.Tensor, *, foreground: torch.Tensor | None = None,
                       foreground_weight: float = 0.0) -> torch.Tensor:
    """Eq. 27: ``1 -`` mean (:func:`split_mean`) over valid pixels of the mean ``|cos|`` to their valid 8 neighbours."""
    n = torch.where(valid, normals, torch.zeros_like(normals))
    h, w = n.shape[-2:]
    npad = F.pad(n, (1, 1, 1, 1))
    vpad = F.pad(valid.to(n.dtype), (1, 1, 1, 1))
    cos_sum = torch.zeros_like(n[:, :1])
    count = torch.zeros_like(n[:, :1])
    for dy, dx in _N8:
        nb = npad[:, :, 1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
        cos_sum = cos_sum + (n * nb).sum(dim=1, keepdim=True).abs()
        count = count + vpad[:, :, 1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
    has = valid & (count > 0)
    return 1.0 - split_mean(cos_sum / count.clamp_min(1.0), has, foreground, weight=foreground_weight)


@dataclass(frozen=True)
class DDDWeights:
    """Eq. 22's lambdas (summing to one) and eq. 23's alpha."""

    photometric: float = 0.85
    depth: float = 0.1
    surface: float = 0.05
    alpha: float = 0.85


class DDDLoss(nn.Module):
    """Eq. 22 for one batch of views (means over views); ``forward`` returns ``(total, {term: value})``.

    Options (keyword-only): ``weights``, ``gamma`` (Charbonnier), ``c_over`` (BerHu threshold over
    ``"valid"`` pixels, the paper, or ``"all"``, the released code), ``ssim_radius`` (None: 11x11),
    ``foreground_weight`` (0: the paper; ``w``: the foreground's share of every mean, :func:`split_mean`,
    with the per-view masks passed to ``forward`` as ``foreground``).
    """

    def __init__(self, *, weights: DDDWeights | None = None, gamma: float = 1e-3, c_over: str = "valid",
                 ssim_radius: int | None = None, foreground_weight: float = 0.0) -> None:
        super().__init__()
        self.w = weights or DDDWeights()
        self.gamma, self.c_over, self.ssim_radius = gamma, c_over, ssim_radius
        self.foreground_weight = foreground_weight

    def forward(self, *, rendered: list[torch.Tensor], targets: list[torch.Tensor], photo_masks: list[torch.Tensor],
                preds: list[torch.Tensor], observed: list[torch.Tensor], valid: list[torch.Tensor],
                normals: list[tuple[torch.Tensor, torch.Tensor]],
                foreground: list[torch.Tensor] | None = None) -> tuple[torch.Tensor, dict]:
        v = len(preds)
        fgs = foreground or [None] * v
        fw = self.foreground_weight
        ph = sum(photometric_loss(r, t, m, alpha=self.w.alpha, gamma=self.gamma, ssim_radius=self.ssim_radius,
                                  foreground=f, foreground_weight=fw)[0]
                 for r, t, m, f in zip(rendered, targets, photo_masks, fgs)) / v
        dp = sum(depth_prior_loss(p, o, m, c_over=self.c_over, foreground=f, foreground_weight=fw)
                 for p, o, m, f in zip(preds, observed, valid, fgs)) / v
        sf = sum(surface_prior_loss(n, ok, foreground=f, foreground_weight=fw) for (n, ok), f in zip(normals, fgs)) / v
        total = self.w.photometric * ph + self.w.depth * dp + self.w.surface * sf
        return total, {"photometric": float(ph.detach()), "depth": float(dp.detach()), "surface": float(sf.detach())}
