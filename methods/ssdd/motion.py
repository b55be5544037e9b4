"""Level 2's optional motion (``[level2.motion]``, not in the paper): the ConvLSTM state and the previous
frame's depth warped into the current frame by a dense optical flow.

Why. The seed's level 2 (``kind = "none"``, the default) carries its ConvLSTM state at the same pixel
from frame to frame. Measured on the simulator (issue 10 worklog, session 6, ``tcorr.py``): the raw LQ
errors are independent frame to frame, level 1's errors are correlated 0.46 on static pixels but
0.02 on moving pixels (truth change > 1 cm), so what level 2 can still gain on moving content is
temporal denoising that follows the motion; a tiny UNet-ConvLSTM does not learn motion in a few
hundred steps (LSTM - UNet on moving pixels over three training seeds: -0.03, -1.44, +0.07 mm^2).

The model. Frame ``t`` of a sequence gets the backward flow ``F_t`` ``(2, H, W)`` pixels: for each
pixel ``x`` of frame ``t``, where it was in frame ``t - 1`` (``x + F_t(x)``; ``F_0 = 0``). It is
OpenCV's DIS (ultrafast preset, :class:`align.motion_flow.ColorFlow`) between grey images of the two
frames: the LQ colour (``kind = "color"``, reduced by ``flow_scale`` as :func:`align.motion_flow.flow_image`
does) or the LQ depth (``kind = "depth"``: 2 cm per grey level around the current frame's median,
:func:`depth_grey`; no colour needed). Then, before level 2 sees frame ``t``:

* ``warp_state``: every ConvLSTM level's ``(h, c)`` is resampled, ``S'(x) = S(x + F_t(x))`` (bilinear,
  :func:`warp`; the flow averaged to the level's resolution and scaled with it), so the state meets
  the frame where its content now is;
* ``previous = "output"``: level 2 also takes its own previous output warped the same way,
  ``P_t = D_2(t-1)(x + F_t(x))``, coded like the level-1 prediction (one more input channel;
  ``P_0`` is frame 0's level-1 prediction); ``"level1"``: the previous level-1 prediction instead;
  ``"none"``: no such channel. With ``P_t`` the net can average the frames where they agree (the
  depth change of a point moving in depth is smooth, the noise is not).

The flow is not learned and has no gradient; the warps are differentiable, so level 2 trains through
them as it runs at inference. Training precomputes each frame's flow on whole frames
(:func:`sequence_flows`, the same :func:`backward_flow` inference calls frame by frame), crops it with
the other layers and negates its x component on flipped samples.

Measured (issue 10 worklog, session 7; tiny's level-2 budget of 240 steps; LSTM - UNet MSE in mm^2,
all / moving pixels, per-frame bootstrap). Selection session 201, level 2 retrained on one level 1: no
motion -0.14 / +0.02; ``kind = "color"`` with ``previous = "output"`` -0.10 / +0.08, ``"level1"`` -0.09 /
+0.05; ``kind = "depth"``, ``"output"`` -0.16 / -0.00; level 2's validation loss stays at level 1's in
every case. Held-out session 202, three training seeds, moving pixels: colour motion +0.13 / -0.15 /
+0.39 against -0.03 / -1.44 / +0.07 without. The cause, measured on 201: carried by the flow, level 1's
errors on moving pixels are correlated 0.41 frame to frame (0.02 at the same pixel; static pixels
0.46), and 86 % of their squared error lies within 2 px of a depth edge: they are silhouette placement
errors that move with the content, not noise that temporal fusion removes (a fixed motion-compensated
recursive filter on level 1's output made the MSE worse at every weight tried). So tiny keeps
``kind = "none"``; the option stays for longer training (``paper``) and real sequences. Its training cost
at tiny's size is within the run-to-run spread (the flow is one DIS pass per frame, computed once).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

KINDS = ("none", "color", "depth")
PREVIOUS = ("none", "level1", "output")
#: depth per grey level of :func:`depth_grey` (m)
DEPTH_GREY_M = 0.02
FLOW_X, FLOW_Y = "flow_x", "flow_y"     # the batch keys (extra layers) of the training flows


@dataclass
class MotionConfig:
    """``kind``: the flow's source, ``"none"`` (the paper's level 2), ``"color"`` or ``"depth"``;
    ``flow_scale``: the grey images are reduced by this factor for the flow (colour only; 1 = full size);
    ``warp_state``: warp the ConvLSTM state; ``previous``: ``"none"``, ``"level1"`` or ``"output"``,
    the previous frame's depth warped into the current frame as one more input (module docstring)."""

    kind: str = "none"
    flow_scale: float = 1.0
    warp_state: bool = True
    previous: str = "output"

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"motion.kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        if self.previous not in PREVIOUS:
            raise ValueError(f"motion.previous must be one of {', '.join(PREVIOUS)}, got {self.previous!r}")
        if not 0 < self.flow_scale <= 1:
            raise ValueError(f"motion.flow_scale must be in (0, 1], got {self.flow_scale}")

    @property
    def enabled(self) -> bool:
        return self.kind != "none"

    @property
    def feeds_previous(self) -> bool:
        """Level 2 takes the warped previous depth as an input channel."""
        return self.enabled and self.previous != "none"


# ---------------------------------------------------------------------------- flow (numpy, OpenCV)
def depth_grey(depth: np.ndarray, centre: float) -> np.ndarray:
    """``depth`` ``(H, W)`` metres (NaN holes) as a grey image: ``128 + (d - centre) / 2 cm``, clipped to
    0..255, holes 0; uint8."""
    g = np.clip(128.0 + (np.nan_to_num(depth, nan=-np.inf) - centre) / DEPTH_GREY_M, 0, 255)
    return g.astype(np.uint8)


def color_grey(color: np.ndarray, *, scale: float = 1.0) -> np.ndarray:
    """The LQ colour ``(H, W, 3)`` RGB or ``(H, W)`` grey (uint8, uint16 or float32 in [0, 1]) as the
    uint8 grey image of :func:`align.motion_flow.flow_image`, reduced by ``scale``."""
    from align.motion_flow import flow_image

    c = np.asarray(color)
    if c.dtype == np.uint16:
        c = (c >> 8).astype(np.uint8)
    elif c.dtype != np.uint8:
        c = np.clip(np.nan_to_num(c.astype(np.float32)) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return flow_image(c, scale=scale)


class FlowSource:
    """The backward flow of a frame into the previous one for one :class:`MotionConfig` (one DIS per
    thread, :class:`align.motion_flow.ColorFlow`)."""

    def __init__(self, cfg: MotionConfig) -> None:
        import cv2

        from align.motion_flow import ColorFlow

        self.cfg = cfg
        # DIS ultrafast at its own finest level, as level 2's motion was measured with (session 7); align's
        # default flow (ColorFlow()) stops one level coarser, tuned for its quarter-size images (session 9)
        self._flow = ColorFlow(cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST)

    def image(self, depth: np.ndarray, color: np.ndarray | None):
        """What the flow of a frame is computed from: its colour (``"color"``) or its depth (``"depth"``)."""
        return depth if self.cfg.kind == "depth" else color

    def __call__(self, cur: np.ndarray, prev: np.ndarray) -> np.ndarray:
        """``F_t`` ``(2, H, W)`` float32 pixels of the current frame's pixels into the previous frame, from
        their :meth:`image` s (depth ``(H, W)`` metres, or colour)."""
        if self.cfg.kind == "depth":
            ok = np.isfinite(cur)
            centre = float(np.median(cur[ok])) if ok.any() else 1.0
            a, b, scale = depth_grey(cur, centre), depth_grey(prev, centre), 1.0
            shape = cur.shape
        else:
            scale = self.cfg.flow_scale
            a, b = color_grey(cur, scale=scale), color_grey(prev, scale=scale)
            shape = np.shape(cur)[:2]
        f = self._flow(a, b)
        if f.shape[:2] != shape:
            import cv2

            f = cv2.resize(f, (shape[1], shape[0]), interpolation=cv2.INTER_LINEAR)
        return np.ascontiguousarray(f.transpose(2, 0, 1) / np.float32(scale), np.float32)


def sequence_flows(images: list, cfg: MotionConfig) -> np.ndarray:
    """``F_t`` of every frame of a sequence from their :meth:`FlowSource.image` s: ``(F, 2, H, W)``
    float32 pixels, frame 0 zeros."""
    src = FlowSource(cfg)
    out = np.zeros((len(images), 2) + np.shape(images[0])[:2], np.float32)
    for t in range(1, len(images)):
        out[t] = src(images[t], images[t - 1])
    return out


# ---------------------------------------------------------------------------- warps (torch)
def warp(x, flow):
    """Backward warp: ``x`` ``(B, C, h, w)`` sampled at ``p + F(p)`` (bilinear, border values outside).

    ``flow`` ``(B, 2, H, W)`` pixels (x, y) of the full-resolution frame; at another resolution it is
    averaged to ``(h, w)`` and scaled by ``w / W`` and ``h / H``."""
    import torch
    import torch.nn.functional as F

    h, w = x.shape[-2:]
    if flow.shape[-2:] != (h, w):
        sx, sy = w / flow.shape[-1], h / flow.shape[-2]
        flow = F.adaptive_avg_pool2d(flow, (h, w)) * flow.new_tensor([sx, sy]).view(1, 2, 1, 1)
    ys = torch.arange(h, dtype=flow.dtype, device=flow.device).view(1, h, 1)
    xs = torch.arange(w, dtype=flow.dtype, device=flow.device).view(1, 1, w)
    gx = (xs + flow[:, 0]) * (2.0 / max(w - 1, 1)) - 1.0
    gy = (ys + flow[:, 1]) * (2.0 / max(h - 1, 1)) - 1.0
    grid = torch.stack([gx, gy], dim=-1).to(x.dtype)
    return F.grid_sample(x, grid, mode="bilinear", padding_mode="border", align_corners=True)


def warp_state(state: dict | None, flow) -> dict | None:
    """Every ConvLSTM level's ``(h, c)`` of ``state`` (:class:`methods.ssdd.networks.UNet`) warped by ``flow``."""
    if not state:
        return state
    return {lv: tuple(warp(s, flow) for s in hc) for lv, hc in state.items()}
