"""Depth scale and offset of the LQ sensor against the HQ reference: ``z_LQ = s z_HQ + o``.

The base model has ``s = 1, o = 0``. Residual of a sampled pixel (relative, so near and far
pixels weigh alike)::

    r = (z_LQ - (s z_ref + o)) / z_ref = r0 - (s - 1) - o / z_ref

linear in ``(s - 1, o)``: the Jacobian columns are ``-1`` (scale) and ``-1 / z_ref`` (offset).
Signature: the depth residual against depth (a scale error is a constant relative residual, an
offset one falling as ``1/z``). Stereo sensors show scale errors of 0.3-1 %.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class DepthData:
    """Sampled pixels of aligned pairs: ``z_ref`` (warped HQ) and ``z_lq`` ``(N,)`` metres, ``pair``
    ``(N,)`` group index (0..G-1 in time order), ``t_us`` ``(N,)`` LQ stamp, ``xy`` ``(N, 2)`` LQ depth
    pixel, ``radius`` ``(N,)`` normalised distance from the principal point."""

    z_ref: np.ndarray
    z_lq: np.ndarray
    pair: np.ndarray
    t_us: np.ndarray
    xy: np.ndarray
    radius: np.ndarray

    def __len__(self) -> int:
        return int(self.z_ref.size)

    def residual(self, scale: float = 1.0, offset_m: float = 0.0) -> np.ndarray:
        return (self.z_lq - (scale * self.z_ref + offset_m)) / self.z_ref


@dataclass(frozen=True)
class DepthEffect:
    """One parameter of the depth model (``name``, its Jacobian column, unit)."""

    name: str
    param: str
    unit: str
    what: str
    declared_as: str
    signature: str = "depth"

    def column(self, d: DepthData) -> np.ndarray:
        return -np.ones_like(d.z_ref) if self.param == "s_minus_1" else -1.0 / d.z_ref


DEPTH_SCALE = DepthEffect("depth_scale", "s_minus_1", "1", "LQ depth is scaled against HQ: z_LQ = s z_HQ",
                          "depth_scale", "constant")
DEPTH_OFFSET = DepthEffect("depth_offset", "o_m", "m", "LQ depth is offset against HQ: z_LQ = z_HQ + o",
                           "depth_offset_mm", "depth")


def depth_effects() -> list[DepthEffect]:
    return [DEPTH_SCALE, DEPTH_OFFSET]
