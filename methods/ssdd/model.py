"""SSDD's forward passes in metres, shared by training, out-of-fold prediction and inference.

Pure functions on tensors: depth ``(N, 1, H, W)`` metres with NaN holes in, metres out (a value
at every pixel: the networks fill holes; callers decide whether to keep them). The networks see
depth in the code of ``data`` (:func:`methods.nn.normalize.encode_depth`: the range coding, or the
centred coding when ``data.depth_scale_m > 0``); level 2 codes the level-1 prediction with the LQ
frame's centre, so both inputs share one code. Where the net's config asks for it
(``model.absolute_depth``), the LQ depth relative to 2 m is fed as well (:func:`absolute_code`).
With a prefilter (``[level1.prefilter]``, :mod:`methods.ssdd.prefilter`) level 1 also takes the
filtered LQ depth, coded with the LQ frame's centre, and corrects it instead of the raw depth.
"""
from __future__ import annotations

import torch

from methods.nn.config import DataConfig
from methods.nn.distributed import unwrap
from methods.nn.losses import masked_l1
from methods.nn.normalize import decode_depth, encode_depth, frame_centre
from methods.ssdd.networks import SSDDLSTMUNet, SSDDUNet


def _code(data: DataConfig) -> dict:
    return {"d_min": data.depth_min_m, "d_max": data.depth_max_m, "scale_m": data.depth_scale_m}


ABSOLUTE_REF_M = 2.0
PREFILTERED = "prefiltered"   # the batch key (extra layer) of level 1's prefiltered base


def absolute_code(net, depth: torch.Tensor) -> torch.Tensor | None:
    """The ``z`` channel of ``net``: ``depth / 2 m - 1`` (0 at 2 m, the reference distance of the
    depth-adaptive bilateral filter; holes 0), or None when its config does not feed it. ``net`` may
    be wrapped by ``DistributedDataParallel`` (its config is then the wrapped module's)."""
    if not unwrap(net).cfg.absolute_depth:
        return None
    return torch.where(torch.isfinite(depth), depth / ABSOLUTE_REF_M - 1.0, torch.zeros_like(depth))


def build_level1(cfg) -> SSDDUNet:
    """A level-1 net for ``cfg`` (:class:`methods.ssdd.config.Level1Config`): it takes the prefiltered
    base as an input when ``cfg.prefilter`` is on."""
    return SSDDUNet(cfg.model, base=cfg.prefilter.enabled)


def level1_depth(net: SSDDUNet, depth: torch.Tensor, rgb: torch.Tensor | None, data: DataConfig,
                 base: torch.Tensor | None = None) -> torch.Tensor:
    """Level 1 on ``depth`` ``(..., 1, H, W)`` metres (and ``rgb`` ``(..., 3, H, W)`` in [0, 1]) -> metres.

    ``base``: the prefiltered LQ depth (same shape, metres; :mod:`methods.ssdd.prefilter`) for a net
    built with ``base=True``, coded with the LQ frame's centre; None otherwise."""
    x, valid, centre = encode_depth(depth, **_code(data))
    xb = None if base is None else encode_depth(base, centre=centre, **_code(data))[0]
    return decode_depth(net(x, valid, rgb, absolute_code(net, depth), xb), centre=centre, **_code(data))


def _level2_inputs(net, level1: torch.Tensor, depth: torch.Tensor, data: DataConfig, centre=None):
    x, valid, centre = encode_depth(depth, centre=centre, **_code(data))
    x1, _, _ = encode_depth(level1, centre=centre, **_code(data))
    return x1, x, valid, centre, absolute_code(net, depth)


def level2_step(net: SSDDLSTMUNet, level1: torch.Tensor, depth: torch.Tensor, rgb: torch.Tensor | None,
                data: DataConfig, state: tuple | None, *, sequence_centre: bool = False) -> tuple[torch.Tensor, tuple]:
    """One frame of level 2: level-1 prediction and LQ depth ``(B, 1, H, W)`` metres -> metres, new state.

    ``state``: None at a sequence's first frame, else what the previous call returned (the ConvLSTM
    state and the frame centre of the code). ``sequence_centre``: code every frame with the first
    frame's centre (:func:`level2_depth`) instead of its own."""
    net_state, centre = state if state is not None else (None, None)
    x1, x, valid, own, z = _level2_inputs(net, level1, depth, data, centre if sequence_centre else None)
    y, net_state = net.step(x1, x, valid, rgb, net_state, z)
    return decode_depth(y, centre=own, **_code(data)), (net_state, own)


def level2_depth(net: SSDDLSTMUNet, level1: torch.Tensor, depth: torch.Tensor, rgb: torch.Tensor | None,
                 data: DataConfig, *, sequence_centre: bool = False) -> torch.Tensor:
    """Level 2 over sequences ``(B, T, 1, H, W)`` (state from zeros at ``t = 0``) -> metres.

    The centred code (``data.depth_scale_m > 0``) is each frame's own median, or with
    ``sequence_centre`` the first frame's for every frame of the sequence: the ConvLSTM state then
    holds depth in the code of the frame it meets (a per-frame median of a crop over a moving person
    jumps by centimetres from frame to frame, which the state cannot tell from motion)."""
    centre = frame_centre(depth[:, :1]) if sequence_centre and data.depth_scale_m > 0 else None
    x1, x, valid, centre, z = _level2_inputs(net, level1, depth, data, centre)
    return decode_depth(net(x1, x, valid, rgb, z), centre=centre, **_code(data))


def _mask(batch: dict, holes: bool) -> torch.Tensor:
    """M_r of eq. 32, restricted to pixels where the LQ sensor measured depth unless ``holes``.

    Without the restriction the loss is dominated by filling the LQ holes (errors of metres on a few
    per cent of the pixels against centimetres of noise elsewhere) and the network trades a bias on
    the measured pixels for it; inference keeps the holes anyway (``fill_holes=false``)."""
    return batch["roi"] if holes else batch["roi"] * torch.isfinite(batch["lq_depth"])


def level1_loss(data: DataConfig, *, holes: bool = False):
    """Eq. 32 loss of level 1 on a training batch (keys of :mod:`methods.nn.data`; the prefiltered
    base, when the net takes one, as the extra layer ``PREFILTERED``)."""
    def loss(net, batch):
        pred = level1_depth(net, batch["lq_depth"], batch["color"], data, batch.get(PREFILTERED))
        return masked_l1(pred, batch["reference"], _mask(batch, holes), batch["valid"])
    return loss


def level2_loss(data: DataConfig, *, holes: bool = False, sequence_centre: bool = False):
    """Eq. 32 loss of level 2 over every frame of a batch of sequences with a ``level1`` layer."""
    def loss(net, batch):
        pred = level2_depth(net, batch["level1"], batch["lq_depth"], batch["color"], data,
                            sequence_centre=sequence_centre)
        return masked_l1(pred, batch["reference"], _mask(batch, holes), batch["valid"])
    return loss
