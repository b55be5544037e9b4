"""Each SSDD network overfits one batch (loss down 10x) and every parameter gets a gradient."""
import pytest
import torch

from methods.nn.config import DataConfig
from methods.nn.losses import masked_l1
from methods.ssdd.model import level1_depth, level2_depth
from methods.ssdd.motion import MotionConfig
from methods.ssdd.networks import NetConfig, SSDDLSTMUNet, SSDDUNet
from methods.ssdd.prefilter import PrefilterConfig, prefilter_frames

DATA = DataConfig(depth_scale_m=0.1)      # the centred coding of the built-in configs


def _batch(T=1, seed=0, B=2):
    g = torch.Generator().manual_seed(seed)
    y, x = torch.meshgrid(torch.arange(32.0), torch.arange(32.0), indexing="ij")
    slope = torch.rand(B, T, 1, 1, 1, generator=g)
    disc = ((x - 16) ** 2 + (y - 12) ** 2 < 40).float()
    truth = 1.5 + 0.02 * slope * x - 0.4 * disc          # a slanted wall and a nearer disc: smooth, learnable
    lq = truth + 0.05 * torch.randn(truth.shape, generator=g)
    lq[torch.rand(lq.shape, generator=g) < 0.05] = float("nan")
    ref = truth.clone()
    ref[torch.rand(ref.shape, generator=g) < 0.05] = float("nan")
    roi = torch.ones_like(ref)
    roi[..., :4] = 0
    rgb = torch.rand(B, T, 3, 32, 32, generator=g)
    return lq, ref, roi, rgb


def _run(net, lq, ref, roi, rgb):
    if isinstance(net, SSDDLSTMUNet):
        l1 = torch.nan_to_num(lq, nan=2.0)
        pred = level2_depth(net, l1, lq, rgb, DATA)
    else:
        pred = level1_depth(net, lq, rgb, DATA, _base(lq) if net.base else None)
    return masked_l1(pred, ref, roi)


def _base(lq):
    """Level 1's bilateral prefilter of every frame of ``lq`` ``(..., 1, H, W)``."""
    frames = lq.reshape(-1, *lq.shape[-2:]).numpy()
    return torch.from_numpy(prefilter_frames(frames, PrefilterConfig(kind="bilateral"))).reshape(lq.shape)


@pytest.mark.parametrize("kind", ["unet", "unet_color", "unet_z", "unet_prefilter", "lstm"])
def test_overfits_one_batch_and_gradients_reach_every_parameter(kind):
    torch.manual_seed(0)
    if kind == "lstm":
        net, batch = SSDDLSTMUNet(NetConfig(width=8, levels=3, recurrent=[-1, 0], absolute_depth=True)), _batch(T=2, B=1)
    else:
        net, batch = SSDDUNet(NetConfig(width=8, levels=3, use_color=kind == "unet_color",
                                        absolute_depth=kind == "unet_z"), base=kind == "unet_prefilter"), _batch()
    loss = _run(net, *batch)
    loss.backward()
    for name, p in net.named_parameters():
        assert p.grad is not None and p.grad.abs().sum() > 0, name
    first = loss.item()
    opt = torch.optim.Adam(net.parameters(), lr=5e-3)
    for _ in range(800):                     # stops as soon as the loss is down 10x
        opt.zero_grad()
        loss = _run(net, *batch)
        if loss.item() < first / 10:
            break
        loss.backward()
        opt.step()
    assert loss.item() < first / 10, (first, loss.item())


def test_lstm_state_carries_information_across_frames():
    torch.manual_seed(0)
    net = SSDDLSTMUNet(NetConfig(width=4, levels=2, recurrent=[-1]))
    lq, _, _, rgb = _batch(T=3)
    l1 = torch.nan_to_num(lq, nan=2.0)
    out = level2_depth(net, l1, lq, rgb, DATA)
    lq2 = lq.clone()
    lq2[:, 0, ..., :16] += 0.5              # change only the first frame (not by a constant: the code is offset-free)
    out2 = level2_depth(net, torch.nan_to_num(lq2, nan=2.0), lq2, rgb, DATA)
    assert (out[:, 2] - out2[:, 2]).abs().max() > 1e-6       # frame 3 depends on frame 1 through the state
    single = SSDDUNet(NetConfig(width=4, levels=2))
    a = level1_depth(single, lq, rgb, DATA)
    b = level1_depth(single, lq2, rgb, DATA)
    assert torch.equal(a[:, 2], b[:, 2])                     # level 1 has no state


@pytest.mark.parametrize("absolute", [False, True])
def test_only_the_absolute_depth_channel_lets_the_correction_depend_on_distance(absolute):
    """The centred code is offset-free: moving a scene 1 m away moves level 1's output by exactly
    1 m (up to float rounding), so the correction cannot grow with distance like stereo noise (z^2).
    ``absolute_depth`` feeds the range-coded depth; the same scene 1 m away then gets another correction."""
    torch.manual_seed(0)
    net = SSDDUNet(NetConfig(width=4, levels=2, absolute_depth=absolute))
    with torch.no_grad():
        net.unet.head.weight.mul_(1000)       # a clearly non-zero correction
    lq, _, _, _ = _batch()
    near = level1_depth(net, lq[:, 0], None, DATA)
    far = level1_depth(net, lq[:, 0] + 1.0, None, DATA)
    shift = far - near - 1.0
    if absolute:
        assert shift.abs().max() > 1e-3
    else:
        assert shift.abs().max() < 1e-5


@pytest.mark.parametrize("motion", [None, MotionConfig(kind="color", previous="output"),
                                    MotionConfig(kind="depth", previous="level1", warp_state=False)])
@pytest.mark.parametrize("sequence_centre", [False, True])
def test_level2_streaming_equals_the_sequence_pass_and_the_sequence_centre_is_the_first_frames(sequence_centre, motion):
    """Inference (``level2_step`` frame by frame, state carried) equals training's pass over the sequence
    (``level2_depth``) for either code, with or without motion (state and previous depth warped by a
    given flow); with ``sequence_centre`` every frame is coded around the first frame's median: shifting
    a later frame by a constant then changes the net's input (its own code would hide the shift), and
    the first frame's output is the same as with per-frame centres."""
    from methods.ssdd.model import level2_step

    torch.manual_seed(0)
    net = SSDDLSTMUNet(NetConfig(width=4, levels=2, recurrent=[-1, 0]), previous=bool(motion and motion.feeds_previous))
    with torch.no_grad():
        net.unet.head.weight.mul_(100.0)          # a visible correction
    lq, _, _, _ = _batch(T=3)
    l1 = torch.nan_to_num(lq, nan=2.0)
    flow = None if motion is None else 2.0 * torch.randn(lq.shape[0], 3, 2, 32, 32)
    kw = {"flow": flow, "motion": motion}
    with torch.no_grad():
        seq = level2_depth(net, l1, lq, None, DATA, sequence_centre=sequence_centre, **kw)
        state, steps = None, []
        for t in range(lq.shape[1]):
            y, state = level2_step(net, l1[:, t], lq[:, t], None, DATA, state, sequence_centre=sequence_centre,
                                   flow=None if flow is None else flow[:, t], motion=motion)
            steps.append(y)
        assert torch.allclose(torch.stack(steps, 1), seq, atol=1e-6)
        own = level2_depth(net, l1, lq, None, DATA, **kw)
        assert torch.allclose(seq[:, 0], own[:, 0], atol=1e-6)
        shifted = level2_depth(net, l1 + 0.3 * (torch.arange(3) == 2).view(1, 3, 1, 1, 1),
                               lq + 0.3 * (torch.arange(3) == 2).view(1, 3, 1, 1, 1), None, DATA,
                               sequence_centre=sequence_centre, **kw)
        moved = (shifted[:, 2] - 0.3 - seq[:, 2]).abs().max().item()
        if sequence_centre:
            assert moved > 1e-4, moved
        elif not net.previous:                    # (a previous depth unshifted is a real change of the input)
            assert moved < 1e-5, moved
        if motion is not None:                    # the flow is used after the first frame
            still = level2_depth(net, l1, lq, None, DATA, sequence_centre=sequence_centre, flow=0 * flow, motion=motion)
            assert torch.equal(still[:, 0], seq[:, 0]) and (still[:, 1:] - seq[:, 1:]).abs().max() > 1e-4
