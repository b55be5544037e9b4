"""Level 1's optional prefilter: the UNet corrects a bilateral-filtered LQ depth instead of the raw one.

The seed's level 1 (``kind = "none"``, the default) learns ``x_lq + UNet(x_lq, ...)`` with eq. 32.
Eq. 32 trains it only where the aligned HQ reference exists, and at depth edges it mostly does
not (occlusion between the sensors and the reference's own edge rule leave 65-70 % of the pixels
within 2 px of a simulated depth edge without a reference): there the net is never told not to
average across the edge, and it invents intermediate depths. With ``kind = "bilateral"`` level 1
is

    D_1 = B + UNet(B, x_lq, valid, ...)          B = bilateral_filter(D_lq)  (eq. 5-8, depth-adaptive)

in the same centred code (:mod:`methods.nn.normalize`; ``B`` is coded with the LQ frame's centre).
The residual starts at zero (small head), so an untrained level 1 *is* the filter, which keeps
edges by its range kernel; eq. 32 then trains the correction of ``B`` wherever a reference exists.
The loss, the data and level 2 are unchanged; inference pays one bilateral filter per frame.

Measured on today's simulator (issue 10 worklog, session 5; tiny's recipe in a bare loop, 500 steps,
held-out seed 201 vs truth, MSE mm^2): raw 313.5, bilateral 107.7, plain level 1 197.7, prefiltered
level 1 96.8 (-10.8 [-11.8, -10.0] vs the filter, per-frame bootstrap); the gain shows both inside
surfaces and within 2 px of edges. The decision was confirmed on a second held-out session (seed 202)
through ``methods train``; see the worklog.

The filter's parameters are part of the config (``[level1.prefilter]``), so a weights file rebuilds
exactly the base it was trained on; the defaults are the swept defaults of the ``bf`` method for
the simulated LQ sensor at the time of writing (``methods/defaults.json``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

KINDS = ("none", "bilateral")


@dataclass
class PrefilterConfig:
    """``kind``: ``"none"`` (the seed's level 1) or ``"bilateral"``; the filter's parameters
    (:func:`methods.bilateral.bilateral_filter`): ``sigma_spatial`` pixels, ``sigma_color`` metres
    (at 2 m when ``depth_adaptive``), ``radius`` pixels (0: ``ceil(2 sigma_spatial)``)."""

    kind: str = "none"
    sigma_spatial: float = 3.0
    sigma_color: float = 0.05
    depth_adaptive: bool = True
    radius: int = 0

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"prefilter.kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        if self.radius < 0:
            raise ValueError(f"prefilter.radius must be >= 0, got {self.radius}")

    @property
    def enabled(self) -> bool:
        return self.kind != "none"


def prefilter(depth: np.ndarray, cfg: PrefilterConfig) -> np.ndarray | None:
    """The base of level 1 for one frame: ``depth`` ``(H, W)`` float32 metres, NaN holes -> the
    bilateral-filtered depth ``(H, W)`` (NaN exactly at the holes), or None when ``cfg`` is off."""
    if not cfg.enabled:
        return None
    from methods.bilateral import bilateral_filter

    return bilateral_filter(depth, sigma_spatial=cfg.sigma_spatial, sigma_color=cfg.sigma_color,
                            radius=cfg.radius or None, depth_adaptive=cfg.depth_adaptive)


def prefilter_frames(frames, cfg: PrefilterConfig) -> np.ndarray | None:
    """:func:`prefilter` of each ``(H, W)`` frame of an iterable -> ``(F, H, W)``, or None when off."""
    if not cfg.enabled:
        return None
    return np.stack([prefilter(d, cfg) for d in frames]).astype(np.float32)
