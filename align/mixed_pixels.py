"""Time-of-flight mixed pixels at the HQ depth image's edges: which samples the reference must not trust.

Pure numpy/OpenCV, no I/O.

Model
-----
A time-of-flight pixel whose footprint straddles a depth edge returns a mix of the two surfaces,
``w z_near + (1 - w) z_far`` (flying pixels). The warp (:mod:`align.warp`, step 2) drops the mixes
that break both of their links along one axis, but a mix within a few percent of one surface passes
its jump and slope tests and is warped as a sample of that surface, one HQ step off the silhouette:
with a 1-3 m jump behind it that is a whole-jump error on the 2-3 LQ pixels it covers. Traced on the
demo session (``perf/reference_error.py``, issue 12), 96 % of the strict reference's squared error
comes from 0.02 % of its ROI pixels, each off by more than 0.3 m, and the same warp of the noise-free
HQ depth has almost none of them: the HQ sensor's mixes, not the warp's geometry, make them. Two
kinds of samples are untrusted here:

* **edge samples that leave their surface's line**: a sample with two samples of its own surface on
  one side and another surface (or no depth) on the other, whose inverse depth differs from the line
  through the first three by more than ``k_sigma`` standard deviations (``w - (4 w_1 + w_2 - 2 w_3) / 3``,
  the least-squares line through samples 1-3 at 0; deviation ``sqrt(1 + 7/3) sigma``, or
  ``sqrt(6) sigma`` from the two-sample line where the third sample is on another surface). ``sigma``
  is the relative noise of inverse depth measured on the frame itself
  (:func:`relative_noise`: median absolute deviation of interior second differences), so the test
  holds on any sensor without its noise model;
* **isolated samples**: both neighbours along one axis on other surfaces (what the warp drops).

What :mod:`align.reference_edges`' ``"mixed"`` rule does with them: they are not warped as surface
samples, but their footprint on the LQ image, at the nearest depth around them, is masked and hides
whatever lies behind it (a mix tells that a nearer surface covers part of that footprint). A mix within
the noise of its surface cannot be told from a true last sample (measured: such samples leave about
one whole-jump error per frame on the demo); only masking a band along every silhouette removes those.
"""
from __future__ import annotations

import cv2
import numpy as np

#: smallest relative noise of inverse depth the edge test assumes (noise-free or quantised input)
MIN_RELATIVE_NOISE = 5e-4


def relative_noise(depth: np.ndarray, *, edge_rel: float = 0.03) -> float:
    """Relative noise ``sigma(w) / w`` of inverse depth ``w = 1 / z`` on one depth image ``(H, W)`` metres
    (NaN = none): 1.4826 x the median absolute deviation of the second differences of ``w`` along rows,
    over triplets on one surface (each step at most ``edge_rel``), divided by ``sqrt(6)``. At least
    :data:`MIN_RELATIVE_NOISE`."""
    w = _inverse(depth)
    a, b, c = w[:, :-2], w[:, 1:-1], w[:, 2:]
    with np.errstate(invalid="ignore"):
        ok = _same(a, b, edge_rel) & _same(c, b, edge_rel)
        s2 = ((a - 2 * b + c) / b)[ok]
    if s2.size < 50:
        return MIN_RELATIVE_NOISE
    mad = float(np.median(np.abs(s2 - np.median(s2)))) * 1.4826
    return max(mad / np.sqrt(6.0), MIN_RELATIVE_NOISE)


def mixed_samples(depth: np.ndarray, *, edge_rel: float = 0.03, k_sigma: float = 3.0,
                  sigma: float | None = None) -> np.ndarray:
    """Samples of a depth image ``(H, W)`` float32 metres (NaN = none) the reference must not trust
    (the module docstring's two kinds): ``(H, W)`` bool.

    Args:
        edge_rel: relative jump between two surfaces (the warp's).
        k_sigma: an edge sample is a mix when it leaves its surface's line by more than this many
            standard deviations.
        sigma: relative noise of inverse depth; ``None``: :func:`relative_noise` of ``depth``.

    Example:
        >>> z = np.full((3, 8), 2.0, np.float32); z[:, 5:] = 4.0; z[1, 4] = 2.3   # a mix at the edge
        >>> mixed_samples(z).astype(int)[1].tolist()
        [0, 0, 0, 0, 1, 0, 0, 0]
    """
    w = _inverse(depth)
    s = relative_noise(depth, edge_rel=edge_rel) if sigma is None else float(sigma)
    H, W = w.shape
    p = 3
    wp = np.full((H + 2 * p, W + 2 * p), np.nan, np.float32)
    wp[p:-p, p:-p] = w

    def at(dy: int, dx: int) -> np.ndarray:
        return wp[p + dy:p + dy + H, p + dx:p + dx + W]

    flag = np.zeros((H, W), bool)
    with np.errstate(invalid="ignore"):
        for sy, sx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
            w1, w2, w3, wo = at(-sy, -sx), at(-2 * sy, -2 * sx), at(-3 * sy, -3 * sx), at(sy, sx)
            line3 = _same(w2, w3, edge_rel)
            pred = np.where(line3, (4 * w1 + w2 - 2 * w3) / 3, 2 * w1 - w2)
            sd = np.where(line3, np.float32(np.sqrt(1 + 7 / 3) * s), np.float32(np.sqrt(6.0) * s))
            edge = _same(w, w1, edge_rel) & _same(w1, w2, edge_rel) & ~_same(w, wo, edge_rel)
            flag |= edge & (np.abs(w - pred) > k_sigma * sd * w)
        # isolated: both neighbours along one axis on other surfaces (or none)
        for (ay, ax) in ((0, 1), (1, 0)):
            flag |= ~_same(w, at(-ay, -ax), edge_rel) & ~_same(w, at(ay, ax), edge_rel)
    return flag & np.isfinite(w)


def nearest_around(depth: np.ndarray) -> np.ndarray:
    """The nearest depth in each sample's 3x3 neighbourhood ``(H, W)`` float32 metres (NaN where none)."""
    z = np.where(np.isfinite(depth), depth, np.inf).astype(np.float32)
    near = cv2.erode(z, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=np.inf)
    return np.where(np.isfinite(near), near, np.float32(np.nan)).astype(np.float32)


def _inverse(depth: np.ndarray) -> np.ndarray:
    d = np.asarray(depth, np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.isfinite(d) & (d > 0), np.float32(1) / d, np.float32(np.nan)).astype(np.float32)


def _same(a: np.ndarray, b: np.ndarray, rel: float) -> np.ndarray:
    """Two inverse depths on one surface: both present and apart by at most ``rel`` of the smaller."""
    return np.abs(a - b) <= np.float32(rel) * np.fmin(a, b)
