"""Synthetic depth for tests and benchmarks: planes and spheres, noise growing with z^2, holes.

Not a sensor simulator (that is ``capture.sim``): a quick, dependency-free scene whose truth is
known exactly, for unit tests and timings.
"""
from __future__ import annotations

import numpy as np


def synthetic_scene(shape: tuple[int, int] = (480, 640), *, seed: int = 0, noise_at_1m: float = 0.003,
                    hole_fraction: float = 0.03) -> tuple[np.ndarray, np.ndarray]:
    """A wall at ~3.5 m, a floor, and spheres (heads, bodies) at 1-3 m.

    Args:
        shape: ``(H, W)`` in pixels (a 60-degree horizontal field of view).
        seed: random seed.
        noise_at_1m: standard deviation of the depth noise at 1 m; it grows like ``z^2`` (stereo).
        hole_fraction: about this fraction of pixels become holes (blobs, plus a band left of each
            sphere's silhouette as in stereo occlusion shadows).

    Returns:
        ``(truth, noisy)``: ``(H, W)`` float32 metres; ``noisy`` has NaN holes, ``truth`` has none.

    Example:
        >>> truth, noisy = synthetic_scene((48, 64), seed=1)
        >>> truth.shape, noisy.dtype, bool(np.isnan(noisy).any()), bool(np.isnan(truth).any())
        ((48, 64), dtype('float32'), True, False)
    """
    H, W = shape
    rng = np.random.default_rng(seed)
    f = 0.5 * W / np.tan(np.radians(30.0))
    cx, cy = (W - 1) / 2.0, (H - 1) / 2.0
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    rx, ry = (u - cx) / f, (v - cy) / f                      # ray directions (x, y, 1)
    depth = np.full((H, W), np.inf)
    # wall: plane z = 3.5 + 0.3 x (slanted)
    wall = 3.5 / (1.0 - 0.3 * rx)
    depth = np.minimum(depth, wall)
    # floor: plane y = 1.2 (camera 1.2 m above the floor, y down)
    with np.errstate(divide="ignore", invalid="ignore"):
        floor = np.where(ry > 1e-3, 1.2 / ry, np.inf)
    depth = np.minimum(depth, floor)
    silhouettes = []
    for _ in range(4):
        z0 = rng.uniform(1.0, 3.0)
        x0 = rng.uniform(-0.4, 0.4) * z0
        for dy, rad in ((-0.55, 0.12), (0.0, 0.28)):          # head, body
            c = np.array([x0, dy, z0])
            # ray-sphere intersection: |t d - c|^2 = rad^2, d = (rx, ry, 1)
            a = rx ** 2 + ry ** 2 + 1.0
            b = -2.0 * (rx * c[0] + ry * c[1] + c[2])
            cc = c @ c - rad ** 2
            disc = b ** 2 - 4 * a * cc
            hit = disc > 0
            t = np.where(hit, (-b - np.sqrt(np.where(hit, disc, 0.0))) / (2 * a), np.inf)
            depth = np.minimum(depth, np.where(t > 0, t, np.inf))
            silhouettes.append(hit)
    truth = depth.astype(np.float32)
    noisy = truth + (noise_at_1m * truth.astype(np.float64) ** 2 * rng.standard_normal((H, W))).astype(np.float32)
    holes = np.zeros((H, W), bool)
    n_blobs = max(1, int(hole_fraction * H * W / 60))
    ys, xs = rng.integers(0, H, n_blobs), rng.integers(0, W, n_blobs)
    for y, x in zip(ys, xs):
        holes[max(0, y - 2):y + 3, max(0, x - 3):x + 3] = True
    for hit in silhouettes:                                  # occlusion shadow: 2 px left of each silhouette
        edge = hit & ~np.roll(hit, 1, axis=1)
        for k in range(1, 3):
            holes |= np.roll(edge, -k, axis=1) & ~hit
    noisy[holes] = np.nan
    return truth, noisy.astype(np.float32)
