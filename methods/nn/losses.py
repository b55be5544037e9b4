"""The masked L1 loss of SSDD, eq. 32 of the seed report.

    L(D_pred, D~_HQ) = || (D_pred - D~_HQ) * M_r * M_NaN ||_1                          (32)

``M_r`` is the region-of-interest mask, ``M_NaN`` the valid-reference mask (the warped HQ depth is
NaN where the HQ sensor saw nothing or the warp left a hole). The difference is taken only where
both masks are 1: a NaN reference never reaches the arithmetic (``NaN * 0`` would be NaN).

Reduction: ``"sum"`` is eq. 32 as printed; ``"mean"`` (the default used in training) divides it by
the number of pixels of the batch, masked or not. Dividing by a constant, not by the count of valid
pixels, keeps the loss of a batch the mean of its samples' losses, so gradients averaged by
DistributedDataParallel over processes equal those of one process with the whole batch.
"""
from __future__ import annotations

import torch
from torch import nn


def masked_l1(pred: torch.Tensor, target: torch.Tensor, roi: torch.Tensor, valid: torch.Tensor | None = None, *,
              reduction: str = "mean") -> torch.Tensor:
    """Eq. 32. All tensors broadcast to one shape (e.g. ``(B, 1, H, W)``), depths in metres.

    Args:
        pred: predicted depth. target: reference depth, NaN = no reference.
        roi: M_r, 0/1 (or bool). valid: M_NaN, 0/1; None = ``isfinite(target)``.
        reduction: ``"sum"`` (eq. 32) or ``"mean"`` (eq. 32 / number of pixels).
    Returns:
        A scalar tensor (metres for ``"mean"``: mean absolute error over all pixels, masked ones as 0).
    """
    if valid is None:
        valid = torch.isfinite(target)
    mask = (roi > 0) & (valid > 0) & torch.isfinite(target)
    diff = torch.where(mask, pred - torch.nan_to_num(target, nan=0.0), torch.zeros_like(pred))
    total = diff.abs().sum()
    if reduction == "sum":
        return total
    if reduction == "mean":
        return total / diff.numel()
    raise ValueError(f"reduction must be 'sum' or 'mean', got {reduction!r}")


class MaskedL1Loss(nn.Module):
    """Eq. 32 as a module; see :func:`masked_l1`."""

    def __init__(self, *, reduction: str = "mean") -> None:
        super().__init__()
        self.reduction = reduction

    def forward(self, pred, target, roi, valid=None):
        return masked_l1(pred, target, roi, valid, reduction=self.reduction)
