"""The time-of-flight flying-pixel weight (``TofNoise.flying_mix``, capture/sim/noise.py) against a
direct per-pixel loop on a step edge: a pixel of the far surface mixes at most half of the near
one in (``"coverage"``), the near surface's at least half; ``"uniform"`` lets far pixels read near."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from capture.sim.errors import SimulationError
from capture.sim.noise import TofNoise, tof_depth

Z_NEAR, Z_FAR = 1.0, 3.0


def _step(h=40, w=40):
    z = np.full((h, w), Z_FAR, np.float32)
    z[:, : w // 2] = Z_NEAR
    z[5:12, 30:34] = Z_NEAR  # a small near block: its far surround sees the near surface on 2 sides
    return z


def _loop_reference(z, noise, seed):
    """The model by hand: per pixel, its 3x3 window's near/far, its own side, the weight."""
    rng = np.random.default_rng(seed)
    pick = rng.random(z.shape) < noise.flying_fraction
    u = rng.random(z.shape, dtype=np.float32)
    out = z.astype(np.float64).copy()
    h, w = z.shape
    for y in range(h):
        for x in range(w):
            win = z[max(y - 1, 0):y + 2, max(x - 1, 0):x + 2]
            lo, hi = float(win.min()), float(win.max())
            if hi - lo <= noise.flying_jump_m or not pick[y, x]:
                continue
            own_near = z[y, x] - lo <= hi - z[y, x]
            c = (0.5 + 0.5 * u[y, x]) if own_near else 0.5 * u[y, x]
            if noise.flying_mix == "uniform":
                wt = u[y, x]
            elif noise.flying_mix == "coverage":
                wt = c
            else:
                a = (hi / lo) ** 2
                wt = c * a / (c * a + 1 - c)
            out[y, x] = wt * lo + (1 - wt) * hi
    return out


@pytest.mark.parametrize("mix", ["uniform", "coverage", "coverage-amplitude"])
def test_flying_mix_matches_a_direct_loop_and_keeps_sides(mix):
    z = _step()
    noise = TofNoise(sigma0_m=0.0, sigma_slope=0.0, flying_mix=mix, min_depth_m=0.1)
    got = tof_depth(z, np.ones_like(z), noise=noise, rng=np.random.default_rng(3)).depth
    ref = _loop_reference(z, noise, 3)
    np.testing.assert_allclose(got, ref, atol=1e-5)
    mid = (Z_NEAR + Z_FAR) / 2
    far_px, near_px = z == Z_FAR, z == Z_NEAR
    mixed = np.abs(got - z) > 1e-3
    assert mixed.sum() > 40  # the edge is mixed at about half its pixels
    far_reads_near = int((far_px & (got < mid - 1e-4)).sum())
    near_reads_far = int((near_px & (got > mid + 1e-4)).sum())
    if mix == "uniform":  # the old model: half of the far side's mixes land nearer than the midpoint
        assert far_reads_near > 3 and near_reads_far > 3
    elif mix == "coverage":
        assert far_reads_near == 0 and near_reads_far == 0
    else:  # the near surface returns (3 / 1)^2 = 9x the light: only the near side is safe
        assert near_reads_far == 0 and far_reads_near > 0


def test_flying_mix_is_checked():
    with pytest.raises(SimulationError, match="flying_mix"):
        TofNoise(flying_mix="linear")


def test_flying_invalid_fraction_drops_that_share_of_the_large_jumps_mixes_and_nothing_else():
    z = _step(80, 80)
    z[40:, :] = Z_NEAR + 0.15  # the lower half: 0.15 m jumps (under flying_invalid_jump_m) to the upper left
    z[40:, 40:] = Z_NEAR + 0.3  # and between the lower quadrants; 1.7 m to the upper right
    base = TofNoise(sigma0_m=0.0, sigma_slope=0.0, min_depth_m=0.1)
    ref = _loop_reference(z, base, 5)  # the same first draws: which pixels mix, and how
    mixed = np.abs(ref - z) > 1e-6
    got = tof_depth(z, np.ones_like(z), noise=TofNoise(sigma0_m=0.0, sigma_slope=0.0, min_depth_m=0.1,
                                                       flying_invalid_fraction=0.7),
                    rng=np.random.default_rng(5)).depth
    gone = ~np.isfinite(got)
    lo = cv2.erode(z, np.ones((3, 3), np.uint8)); hi = cv2.dilate(z, np.ones((3, 3), np.uint8))
    small = mixed & (hi - lo < 0.2)
    assert small.sum() > 20 and not (gone & small).any()  # mixes across jumps under 0.2 m stay
    mixed &= ~small
    assert not (gone & ~mixed).any()  # only mixes are dropped
    np.testing.assert_allclose(got[~gone], ref[~gone], atol=1e-5)
    share = gone.sum() / mixed.sum()
    n = mixed.sum()
    assert abs(share - 0.7) < 4 * np.sqrt(0.21 / n), (share, n)
