"""SSDD's two networks: a UNet (level 1) and a UNet with ConvLSTM state (level 2).

Both predict a correction of their first input channel (residual learning) in normalised depth
units (:mod:`methods.nn.normalize`):

* level 1, :class:`SSDDUNet`: input ``[x_lq, valid_lq?, rgb?, z?]`` -> ``x_lq + UNet(...)``, or with a
  prefiltered base ``x_b`` (``base=True``, :mod:`methods.ssdd.prefilter`): ``[x_b, x_lq, valid_lq?, rgb?, z?]``
  -> ``x_b + UNet(...)``;
* level 2, :class:`SSDDLSTMUNet`: input ``[x_l1, x_lq, x_prev?, valid_lq?, rgb?, z?]`` -> ``x_l1 + UNet(...)``,
  where ``x_l1`` is the level-1 prediction; ConvLSTM cells at the chosen levels (by default the
  bottleneck) carry state from frame to frame of a sequence; ``x_prev`` (``previous=True``, not in the
  paper) is the previous frame's depth warped into this one (:mod:`methods.ssdd.motion`).

``z`` (``absolute_depth``, off in the built-in configs) is the LQ depth as ``d / 2 m - 1``
(:func:`methods.ssdd.model.absolute_code`): the centred coding of ``x`` hides how far a surface
is, and stereo noise grows as ``z^2`` (the depth-adaptive bilateral filter widens its range kernel
the same way); with this channel the correction can follow the distance. Measured (issue 10
worklog, 2026-11-23): held-out MSE -43 and -104 mm^2 in a bare training loop at 500 steps (two
seeds), but no gain through ``methods train`` with the tiny recipe for a range-coded variant
(730 vs 725 mm^2): within the run-to-run spread, so not enabled.

Shapes: single frames ``(B, C, H, W) -> (B, 1, H, W)``; sequences ``(B, T, C, H, W) -> (B, T, 1, H, W)``.
Any ``H, W`` works (the decoder resizes to each skip connection, odd sizes are padded for the
stem); ``perf/ssdd_inference.py`` times a 640x480 frame by width.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import torch
import torch.nn.functional as F
from torch import nn

from methods.nn.convlstm import ConvLSTMCell
from methods.nn.layers import NORMS, ConvBlock, Down, Up, level_widths


@dataclass
class NetConfig:
    """A UNet's shape and inputs.

    ``width``: channels of the first level (doubling per level); ``levels``: resolutions (the
    bottleneck is ``levels - 1``); ``use_mask``: feed the LQ validity mask; ``use_color``: feed
    the LQ colour; ``recurrent``: levels with a ConvLSTM cell (level 2 only; -1 = bottleneck);
    ``stem``: space-to-depth factor of the input (1: the first block at full resolution; 2 or 4:
    cheaper, but the per-pixel correction is then made at a coarser grid and learns more slowly);
    ``norm``: ``"none"`` (default) or ``"group"`` (GroupNorm: per-sample normalised features lose
    the input's scale, and the residual correction with it; the nets stayed at the identity);
    ``absolute_depth``: feed the LQ depth relative to 2 m as one more channel (see the module docstring).
    """

    width: int = 16
    levels: int = 4
    use_mask: bool = True
    use_color: bool = False
    recurrent: list[int] = field(default_factory=list)
    stem: int = 1
    norm: str = "none"
    absolute_depth: bool = False

    def __post_init__(self) -> None:
        if self.norm not in NORMS:
            raise ValueError(f"model.norm must be one of {', '.join(NORMS)}, got {self.norm!r}")
        if self.stem not in (1, 2, 4):
            raise ValueError(f"model.stem must be 1, 2 or 4, got {self.stem}")
        if self.width < 2 or self.levels < 1 or self.levels > 7:
            raise ValueError(f"model.width must be >= 2 and model.levels 1..7, got {self.width}, {self.levels}")
        bad = [r for r in self.recurrent if not -self.levels <= r < self.levels]
        if bad:
            raise ValueError(f"model.recurrent: level {bad[0]} does not exist in a {self.levels}-level UNet")

    def recurrent_levels(self) -> list[int]:
        return sorted({r % self.levels for r in self.recurrent})

    def extra_channels(self) -> int:
        return int(self.use_mask) + 3 * int(self.use_color) + int(self.absolute_depth)

    def optional(self, valid, rgb, z) -> list:
        """The optional input layers this config feeds, in channel order (None where not fed)."""
        return [valid if self.use_mask else None, rgb if self.use_color else None,
                z if self.absolute_depth else None]


class UNet(nn.Module):
    """UNet with optional ConvLSTM cells: ``step(x, state) -> (residual (B, 1, H, W), state)``.

    ``state`` maps a recurrent level to its ConvLSTM ``(h, c)``; ``None`` starts a sequence.
    A cell's output is added to the level's features (the feed-forward path stays intact).
    """

    def __init__(self, c_in: int, *, width: int, levels: int, recurrent: list[int] = (), stem: int = 1,
                 norm: str = "group") -> None:
        super().__init__()
        widths = level_widths(width, levels)
        self.recurrent = list(recurrent)
        self.stem = stem
        self.inc = ConvBlock(c_in * stem * stem, widths[0], norm=norm)
        self.downs = nn.ModuleList(Down(widths[i - 1], widths[i], norm=norm) for i in range(1, levels))
        self.cells = nn.ModuleDict({str(lv): ConvLSTMCell(widths[lv], widths[lv]) for lv in self.recurrent})
        self.ups = nn.ModuleList(Up(widths[i], widths[i - 1], widths[i - 1], norm=norm) for i in range(levels - 1, 0, -1))
        self.head = nn.Conv2d(widths[0], stem * stem, 1)
        with torch.no_grad():   # start near the identity (small residual), but let gradients flow everywhere
            self.head.weight.mul_(0.01)
            self.head.bias.zero_()

    def step(self, x: torch.Tensor, state: dict | None = None) -> tuple[torch.Tensor, dict]:
        state = state or {}
        new: dict = {}
        feats = []
        size = x.shape[-2:]
        if self.stem > 1:
            pad_h, pad_w = (-size[0]) % self.stem, (-size[1]) % self.stem
            if pad_h or pad_w:
                x = F.pad(x, (0, pad_w, 0, pad_h), mode="replicate")
            x = F.pixel_unshuffle(x, self.stem)
        if self.inc.body[0].weight.is_contiguous(memory_format=torch.channels_last):
            x = x.contiguous(memory_format=torch.channels_last)   # the input follows the weights' layout
        h = self.inc(x)
        for lv in range(len(self.downs) + 1):
            if lv > 0:
                h = self.downs[lv - 1](h)
            if str(lv) in self.cells:
                out, new[lv] = self.cells[str(lv)](h, state.get(lv))
                h = h + out
            feats.append(h)
        for up, skip in zip(self.ups, reversed(feats[:-1])):
            h = up(h, skip)
        out = self.head(h)
        if self.stem > 1:
            out = F.pixel_shuffle(out, self.stem)[..., :size[0], :size[1]]
        return out, new


def _inputs(first: torch.Tensor, others: list[torch.Tensor | None]) -> torch.Tensor:
    return torch.cat([first] + [o for o in others if o is not None], dim=-3)


class SSDDUNet(nn.Module):
    """Level 1: ``forward(x_lq, valid=None, rgb=None, z=None, x_base=None)`` on ``(..., 1|3, H, W)`` ->
    normalised depth ``(..., 1, H, W)``.

    ``base=True``: the net also takes ``x_base`` (a prefiltered LQ depth in the same code, required)
    as its first channel and corrects it instead of ``x_lq``.
    """

    def __init__(self, cfg: NetConfig, *, base: bool = False) -> None:
        super().__init__()
        self.cfg = cfg
        self.base = bool(base)
        self.unet = UNet(1 + int(self.base) + cfg.extra_channels(), width=cfg.width, levels=cfg.levels,
                         stem=cfg.stem, norm=cfg.norm)

    def forward(self, x_lq: torch.Tensor, valid: torch.Tensor | None = None, rgb: torch.Tensor | None = None,
                z: torch.Tensor | None = None, x_base: torch.Tensor | None = None) -> torch.Tensor:
        if self.base != (x_base is not None):
            raise ValueError("this level-1 net " + ("needs" if self.base else "takes no") + " prefiltered base x_base")
        first, others = (x_base, [x_lq]) if self.base else (x_lq, [])
        x = _inputs(first, others + self.cfg.optional(valid, rgb, z))
        lead = x.shape[:-3]
        flat = x.reshape(-1, *x.shape[-3:])
        res, _ = self.unet.step(flat)
        return first + res.reshape(*lead, *res.shape[-3:])


class SSDDLSTMUNet(nn.Module):
    """Level 2, one frame at a time: :meth:`step` processes one frame ``(B, C, H, W)`` with a carried state.

    Sequences ``(B, T, ...)`` go through :func:`methods.ssdd.model.level2_depth` (training) and
    :func:`methods.ssdd.model.level2_step` (streaming inference), which code the depth and carry the motion
    around each step: the module has no ``forward`` of its own (its old one looped over the frames a second
    way, without the coding, and nothing called it). ``previous=True``: :meth:`step` also takes ``x_prev``
    (required; :func:`methods.ssdd.model.level2_step` makes it).
    """

    def __init__(self, cfg: NetConfig, *, previous: bool = False) -> None:
        super().__init__()
        self.cfg = cfg
        self.previous = bool(previous)
        self.unet = UNet(2 + int(self.previous) + cfg.extra_channels(), width=cfg.width, levels=cfg.levels,
                         recurrent=cfg.recurrent_levels(), stem=cfg.stem, norm=cfg.norm)

    def step(self, x_l1, x_lq, valid=None, rgb=None, state: dict | None = None, z=None,
             x_prev=None) -> tuple[torch.Tensor, dict]:
        if self.previous != (x_prev is not None):
            raise ValueError("this level-2 net " + ("needs" if self.previous else "takes no") + " previous depth x_prev")
        x = _inputs(x_l1, [x_lq, x_prev] + self.cfg.optional(valid, rgb, z))
        res, state = self.unet.step(x, state)
        return x_l1 + res, state
