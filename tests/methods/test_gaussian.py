"""Hole-aware normalised Gaussian (eq. 10 over valid pixels) against a direct loop."""
import math

import numpy as np
import pytest

from methods import MethodError
from methods.gaussian import gaussian_filter


def gaussian_loop(I, sigma_s, radius, *, fill=False):
    H, W = I.shape
    out = np.full((H, W), np.nan)
    for y in range(H):
        for x in range(W):
            if math.isnan(I[y, x]) and not fill:
                continue
            num = den = 0.0
            for j in range(-radius, radius + 1):
                for i in range(-radius, radius + 1):
                    yy, xx = y + j, x + i
                    if i * i + j * j <= radius * radius and 0 <= yy < H and 0 <= xx < W and not math.isnan(I[yy, xx]):
                        w = math.exp(-(i * i + j * j) / (2 * sigma_s ** 2))
                        num += w * float(I[yy, xx])
                        den += w
            if den > 0:
                out[y, x] = num / den
    return out


@pytest.mark.parametrize("fill", [False, True])
def test_matches_loop_reference(fill):
    rng = np.random.default_rng(7)
    I = (1.0 + 2.0 * rng.random((11, 15))).astype(np.float32)
    I[2:5, 3:9] = np.nan
    ours = gaussian_filter(I, sigma_spatial=1.3, radius=3, fill_holes=fill)
    np.testing.assert_allclose(ours, gaussian_loop(I, 1.3, 3, fill=fill), rtol=0, atol=2e-6)


def test_isolated_pixel_without_neighbours_stays_nan_when_filling():
    I = np.full((9, 9), np.nan, np.float32)
    I[0, 0] = 2.0
    out = gaussian_filter(I, sigma_spatial=1.0, radius=2, fill_holes=True)
    assert out[0, 0] == np.float32(2.0) and out[1, 1] == np.float32(2.0) and np.isnan(out[8, 8])


def test_negative_sigma():
    with pytest.raises(MethodError, match="sigma_spatial must be a positive"):
        gaussian_filter(np.ones((4, 4), np.float32), sigma_spatial=-1)
