"""bench.diagnose.stats.edge_errors and jump_pixels: a floor seen at a grazing angle has no edge, however far apart
its rows' depths are; a real step has its band and its flying pixel counted exactly; the doctests."""
from __future__ import annotations

import doctest

import numpy as np

import bench.diagnose.stats
from bench.diagnose.stats import edge_errors, jump_pixels


def test_doctests():
    assert doctest.testmod(bench.diagnose.stats).failed == 0


def _grazing_floor(h: int = 60, w: int = 40, f: float = 200.0, height_m: float = 1.0) -> np.ndarray:
    """The depth of a floor ``height_m`` below a level camera (focal ``f`` px, horizon at row -30): rows 12 cm
    apart near the top, a few mm at the bottom."""
    rows = np.arange(h, dtype=np.float64)[:, None] + 30.0
    return np.tile(height_m * f / rows, (1, w)).astype(np.float32)


def test_a_grazing_floor_has_no_edges():
    z = _grazing_floor()
    assert np.max(np.abs(np.diff(z, axis=0))) > 0.1  # more than the jump from row to row
    assert not jump_pixels(z, jump_m=0.1).any()
    e = edge_errors(z, z)
    assert e.pixels == 0


def test_a_step_counts_its_band_and_its_flying_pixel():
    h, w, c = 30, 40, 20
    ref = np.where(np.arange(w) < c, 1.0, 2.0).astype(np.float32)[None, :].repeat(h, axis=0)
    depth = ref.copy()
    depth[10, c] = 1.5  # between the two sides
    depth[5, c - 2] = 1.0 + 0.001  # on its own side
    e = edge_errors(depth, ref, band_px=2)
    # edge pixels: columns c-1 and c (their 3x3 spans the jump); the band: within 2 px of them, c-3 .. c+2
    assert e.pixels == 6 * h
    assert e.flying_fraction == 1 / (6 * h)
    assert e.missing_fraction == 0.0
    # the same step on the grazing floor: found, and nothing away from it (the floor's slope widens its band)
    floor = _grazing_floor(h=h, w=w)
    both = np.where(np.arange(w) < c, floor - 0.5, floor).astype(np.float32)
    cols = np.flatnonzero(jump_pixels(both, jump_m=0.1).any(axis=0))
    assert cols.min() >= c - 3 and cols.max() <= c + 2
    assert 6 * h <= edge_errors(both, both, band_px=2).pixels <= 10 * h
