"""The optional reference gate of SSDD's loss (``[level1.gate]``, ``[level2.gate]``; not in the paper).

Eq. 32 trains on every pixel of the region of interest where the warped HQ reference exists. Where
the LQ sensor measured depth, its value is the truth plus its noise, so a reference far outside the
LQ's noise is not the truth there: it is the warp's or the motion step's mistake (the HQ sensor saw
another surface from its viewpoint, or the reference carried to the LQ instant put a moving
silhouette elsewhere). The gate drops those pixels from the loss:

    G = |D~_HQ - D_lq| <= floor_m + sigmas * noise_z2 * D_lq^2          (D_lq measured)

``noise_z2 * z^2`` is the stereo LQ sensor's depth noise (m) at depth ``z`` (m): ``z^2 s / (f B)``
(:meth:`capture.sim.noise.StereoNoise.sigma_z`; 0.00242 m at 1 m for the simulated D415-like LQ
sensor at any image scale, the depth error being kept by :func:`capture.sim.noise.in_pixels`).
``floor_m`` covers the reference's own noise and the depth-independent part. ``sigmas = 0`` (the
default) turns the gate off: the paper's loss. Pixels where the LQ has no depth are gated out as
well (they are out of the default loss anyway: ``loss_on_holes = false``).

Why (issue 10 worklog, session 8, ``gate.py`` on the demo's training corpus, ROI pixels with LQ depth
and a reference): the reference against truth on moving pixels within 2 px of a depth edge has MSE
2506 mm^2 (8.5 % of them off by more than 3 cm; on the held-out session 201, 18248 mm^2), inside
moving surfaces 82 mm^2, on static pixels 990 mm^2; with ``sigmas = 3`` (``floor_m = 5 mm``) 95 %,
99.5 % and 99.7 % of those pixels are kept and the reference's MSE there falls to 189, 37 and
13 mm^2. Measured with ``tiny``'s recipe (both levels gated) on the held-out session 202 against truth,
three training seeds, level 1's MSE against the ungated level 1 (per-frame bootstrap): ``sigmas = 2`` (tiny)
-6.69 [-7.02, -6.35], -3.06 [-3.50, -2.63], -4.83 [-5.70, -3.95] mm^2; ``sigmas = 3`` -4.44 [-4.96, -3.94],
-0.38 [-0.52, -0.24], -1.63 [-2.16, -1.09] (2 sigma was chosen on session 201, seed 0: -1.90 [-2.22, -1.58]
against 3 sigma; 5 sigma there +5.81, within single-seed training noise of no gate). Level 2 gains nothing
from it (LSTM - UNet on moving pixels, 2 sigma: -0.22 / +0.49 / +0.74 mm^2; 3 sigma: +0.34 / -0.26 / +0.28).

The gate selects on ``|ref - lq|``, which for a right reference is the LQ's own noise: a gate much
narrower than that noise would keep only pixels where the LQ happens to be right and teach the net to
trust the LQ. At 2 sigma of a matching noise model at most ~5 % of the right references are dropped (the tails); for
another sensor set ``noise_z2`` to its noise.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

#: the simulated stereo LQ sensor's depth noise per squared metre of depth (m / m^2): z^2 s / (f B)
#: with the built-in StereoNoise (subpixel 0.08 px at f = 600 px, B = 0.055 m)
STEREO_NOISE_Z2 = 0.08 / (600.0 * 0.055)


@dataclass
class GateConfig:
    """``sigmas``: the gate's width in LQ noise standard deviations (0: off, the paper's loss);
    ``floor_m``: metres added to it; ``noise_z2``: the LQ depth noise in metres per squared metre of
    depth (module docstring)."""

    sigmas: float = 0.0
    floor_m: float = 0.005
    noise_z2: float = STEREO_NOISE_Z2

    def __post_init__(self) -> None:
        if not (self.sigmas >= 0 and self.floor_m >= 0 and self.noise_z2 >= 0):
            raise ValueError(f"gate.sigmas, gate.floor_m and gate.noise_z2 must be >= 0, got "
                             f"{self.sigmas}, {self.floor_m}, {self.noise_z2}")

    @property
    def enabled(self) -> bool:
        return self.sigmas > 0


def reference_gate(reference: torch.Tensor, lq_depth: torch.Tensor, cfg: GateConfig) -> torch.Tensor:
    """``G`` of the module docstring: a bool tensor of the inputs' shape (metres, NaN = none), True where
    the reference is within the gate of the LQ depth; all True when ``cfg`` is off."""
    if not cfg.enabled:
        return torch.ones_like(reference, dtype=torch.bool)
    bound = cfg.floor_m + cfg.sigmas * cfg.noise_z2 * torch.nan_to_num(lq_depth, nan=0.0) ** 2
    return torch.isfinite(reference) & torch.isfinite(lq_depth) & ((reference - lq_depth).abs() <= bound)
