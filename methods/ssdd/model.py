"""SSDD's forward passes in metres, shared by training, out-of-fold prediction and inference.

Pure functions on tensors: depth ``(N, 1, H, W)`` metres with NaN holes in, metres out (a value
at every pixel: the networks fill holes; callers decide whether to keep them). The networks see
depth in the code of ``data`` (:func:`methods.nn.normalize.encode_depth`: the range coding, or the
centred coding when ``data.depth_scale_m > 0``); level 2 codes the level-1 prediction with the LQ
frame's centre, so both inputs share one code. Where the net's config asks for it
(``model.absolute_depth``), the LQ depth relative to 2 m is fed as well (:func:`absolute_code`).
With a prefilter (``[level1.prefilter]``, :mod:`methods.ssdd.prefilter`) level 1 also takes the
filtered LQ depth, coded with the LQ frame's centre, and corrects it instead of the raw depth. With
motion (``[level2.motion]``, :mod:`methods.ssdd.motion`) level 2's state and previous depth are warped
by each frame's optical flow before the frame is seen.
"""
from __future__ import annotations

import torch

from methods.nn.config import DataConfig
from methods.nn.distributed import unwrap
from methods.nn.losses import masked_l1
from methods.nn.normalize import decode_depth, encode_depth
from methods.ssdd.gate import GateConfig, reference_gate
from methods.ssdd.motion import FLOW_X, FLOW_Y, MotionConfig, warp, warp_state
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


def build_level2(cfg) -> SSDDLSTMUNet:
    """A level-2 net for ``cfg`` (:class:`methods.ssdd.config.Level2Config`): it takes the warped previous
    depth as an input when ``cfg.motion`` feeds it (:mod:`methods.ssdd.motion`)."""
    return SSDDLSTMUNet(cfg.model, previous=cfg.motion.feeds_previous)


def level2_step(net: SSDDLSTMUNet, level1: torch.Tensor, depth: torch.Tensor, rgb: torch.Tensor | None,
                data: DataConfig, state: tuple | None, *, sequence_centre: bool = False,
                flow: torch.Tensor | None = None, motion: MotionConfig | None = None) -> tuple[torch.Tensor, tuple]:
    """One frame of level 2: level-1 prediction and LQ depth ``(B, 1, H, W)`` metres -> metres, new state.

    ``state``: None at a sequence's first frame, else what the previous call returned (the ConvLSTM
    state, the frame centre of the code and the previous depth kept for the motion). ``sequence_centre``:
    code every frame with the first frame's centre (:func:`level2_depth`) instead of its own.
    ``motion`` (:class:`methods.ssdd.motion.MotionConfig`; None: off) with ``flow`` ``(B, 2, H, W)``, this
    frame's backward flow into the previous frame in pixels (ignored at a sequence's first frame): the
    state and the previous depth are warped into this frame first."""
    net_state, centre, prev = state if state is not None else (None, None, None)
    moving = motion is not None and motion.enabled and state is not None
    if moving and flow is None:
        raise ValueError("level 2 with motion needs the flow of every frame after the first")
    if moving and motion.warp_state:
        net_state = warp_state(net_state, flow)
    x1, x, valid, own, z = _level2_inputs(net, level1, depth, data, centre if sequence_centre else None)
    xp = None
    if net.previous:
        p = level1 if prev is None else warp(prev, flow) if moving else prev
        xp = encode_depth(p, centre=own, **_code(data))[0]
    y, net_state = net.step(x1, x, valid, rgb, net_state, z, x_prev=xp)
    out = decode_depth(y, centre=own, **_code(data))
    keep = None if motion is None or not motion.feeds_previous else out if motion.previous == "output" else level1
    return out, (net_state, own, keep)


def level2_depth(net: SSDDLSTMUNet, level1: torch.Tensor, depth: torch.Tensor, rgb: torch.Tensor | None,
                 data: DataConfig, *, sequence_centre: bool = False, flow: torch.Tensor | None = None,
                 motion: MotionConfig | None = None) -> torch.Tensor:
    """Level 2 over sequences ``(B, T, 1, H, W)`` (state from zeros at ``t = 0``) -> metres: :func:`level2_step`
    frame by frame, so training's pass is inference's (``flow`` ``(B, T, 2, H, W)`` with ``motion``).

    The centred code (``data.depth_scale_m > 0``) is each frame's own median, or with
    ``sequence_centre`` the first frame's for every frame of the sequence: the ConvLSTM state then
    holds depth in the code of the frame it meets (a per-frame median of a crop over a moving person
    jumps by centimetres from frame to frame, which the state cannot tell from motion)."""
    state, outs = None, []
    at = lambda v, t: None if v is None else v[:, t]  # noqa: E731
    for t in range(level1.shape[1]):
        y, state = level2_step(net, level1[:, t], depth[:, t], at(rgb, t), data, state,
                               sequence_centre=sequence_centre, flow=at(flow, t), motion=motion)
        outs.append(y)
    return torch.stack(outs, dim=1)


def batch_flow(batch: dict) -> torch.Tensor | None:
    """The training flows of a batch ``(B, T, 2, h, w)`` from its extra layers (:mod:`methods.ssdd.motion`),
    the x component negated on horizontally flipped samples; None when the batch has none."""
    if FLOW_X not in batch:
        return None
    sign = 1.0 - 2.0 * batch["flip"].to(batch[FLOW_X].dtype).view(-1, 1, 1, 1, 1)
    return torch.cat([batch[FLOW_X] * sign, batch[FLOW_Y]], dim=2)


def _mask(batch: dict, holes: bool, gate: GateConfig | None = None) -> torch.Tensor:
    """M_r of eq. 32, restricted to pixels where the LQ sensor measured depth unless ``holes``, and to
    the reference gate's pixels with ``gate`` (:mod:`methods.ssdd.gate`; None or off: no gate).

    Without the restriction the loss is dominated by filling the LQ holes (errors of metres on a few
    per cent of the pixels against centimetres of noise elsewhere) and the network trades a bias on
    the measured pixels for it; inference keeps the holes anyway (``fill_holes=false``)."""
    m = batch["roi"] if holes else batch["roi"] * torch.isfinite(batch["lq_depth"])
    if gate is not None and gate.enabled:
        m = m * reference_gate(batch["reference"], batch["lq_depth"], gate)
    return m


def level1_loss(data: DataConfig, *, holes: bool = False, gate: GateConfig | None = None):
    """Eq. 32 loss of level 1 on a training batch (keys of :mod:`methods.nn.data`; the prefiltered
    base, when the net takes one, as the extra layer ``PREFILTERED``), on the ``gate``'s pixels."""
    def loss(net, batch):
        pred = level1_depth(net, batch["lq_depth"], batch["color"], data, batch.get(PREFILTERED))
        return masked_l1(pred, batch["reference"], _mask(batch, holes, gate), batch["valid"])
    return loss


def offset_free_target(reference: torch.Tensor, level1: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """The reference shifted so that level 2 learns no uniform offset (``level2.offset = "level1"``,
    :mod:`methods.ssdd.config`): ``reference - median_M(reference - level1)`` with the median over the pixels
    of ``mask`` of each image (the last three dimensions, ``(..., 1, H, W)``; an image without one is left as
    it is). Against it, eq. 32's best uniform shift of an image is level 1's own offset."""
    m = (mask > 0) & torch.isfinite(reference) & torch.isfinite(level1)
    r = torch.where(m, reference - level1, torch.full_like(reference, float("nan")))
    off = torch.nan_to_num(torch.nanmedian(r.flatten(start_dim=-3), dim=-1).values, nan=0.0)
    return reference - off[..., None, None, None]


def level2_loss(data: DataConfig, *, holes: bool = False, sequence_centre: bool = False,
                motion: MotionConfig | None = None, gate: GateConfig | None = None, offset: str = "free"):
    """Eq. 32 loss of level 2 over every frame of a batch of sequences with a ``level1`` layer (and the
    flow layers :data:`methods.ssdd.motion.FLOW_X`, ``FLOW_Y`` with ``motion``), on the ``gate``'s pixels;
    with ``offset = "level1"`` against :func:`offset_free_target` (each frame of each crop)."""
    def loss(net, batch):
        pred = level2_depth(net, batch["level1"], batch["lq_depth"], batch["color"], data,
                            sequence_centre=sequence_centre, flow=batch_flow(batch), motion=motion)
        mask, ref = _mask(batch, holes, gate), batch["reference"]
        if offset == "level1":
            ref = offset_free_target(ref, batch["level1"], mask * batch["valid"])
        return masked_l1(pred, ref, mask, batch["valid"])
    return loss
