"""Eq. 32 (masked L1) against a direct loop over pixels."""
import math

import numpy as np
import pytest
import torch

from methods.nn.losses import MaskedL1Loss, masked_l1


def _direct(pred, target, roi):
    """Eq. 32 written out pixel by pixel: |D_pred - D_HQ| summed where M_r = 1 and the reference is a number."""
    total = 0.0
    for p, t, r in zip(pred.ravel(), target.ravel(), roi.ravel()):
        if r and not math.isnan(t):
            total += abs(p - t)
    return total


def test_masked_l1_ignores_nan_reference_and_outside_roi():
    rng = np.random.default_rng(3)
    pred = rng.normal(2.0, 0.3, (2, 1, 4, 5))
    target = rng.normal(2.0, 0.3, (2, 1, 4, 5))
    target[0, 0, 1, 2] = np.nan
    target[1, 0, 3, :] = np.nan
    roi = rng.random((2, 1, 4, 5)) > 0.3
    pred[~roi] = 1e6           # huge errors outside the ROI must not count
    expected = _direct(pred, target, roi)
    p, t, r = (torch.tensor(a) for a in (pred, target, roi.astype(np.float64)))
    assert masked_l1(p, t, r, reduction="sum").item() == pytest.approx(expected, rel=1e-12)
    assert masked_l1(p, t, r).item() == pytest.approx(expected / pred.size, rel=1e-12)
    assert MaskedL1Loss()(p, t, r).item() == pytest.approx(expected / pred.size, rel=1e-12)


def test_masked_l1_gradient_is_finite_and_zero_where_masked():
    target = torch.tensor([[1.0, float("nan")], [2.0, 3.0]])
    roi = torch.tensor([[1.0, 1.0], [0.0, 1.0]])
    pred = torch.tensor([[1.5, 9.0], [9.0, 2.0]], requires_grad=True)
    masked_l1(pred, target, roi, reduction="sum").backward()
    assert torch.equal(pred.grad, torch.tensor([[1.0, 0.0], [0.0, -1.0]]))


def test_explicit_valid_mask_is_applied_too():
    pred = torch.zeros(1, 1, 1, 3)
    target = torch.ones(1, 1, 1, 3)
    valid = torch.tensor([[[[1.0, 0.0, 1.0]]]])
    assert masked_l1(pred, target, torch.ones_like(pred), valid, reduction="sum").item() == 2.0
