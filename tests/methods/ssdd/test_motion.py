"""Level 2's motion (methods.ssdd.motion, not in the paper): the flow, the warps against direct formulas,
flows kept registered under crops and flips, the Denoiser's streaming pass equal to training's sequence
pass, and the leaderboard's config column naming the options that are not in the paper."""
import numpy as np
import pytest
import torch

from align.dataset import AlignedDataset, AlignedDatasetWriter
from bench.report import _not_in_paper
from capture.camera import Intrinsics
from methods.base import FrameInput
from methods.nn.checkpoint import save_tensors
from methods.nn.config import ConfigError, DataConfig, from_dict, to_dict
from methods.nn.data import AlignedSamples
from methods.registry import get
from methods.ssdd.config import Level1Config, Level2Config, SSDDConfig
from methods.ssdd.model import batch_flow, build_level1, build_level2, level1_depth, level2_depth
from methods.ssdd.motion import FLOW_X, FLOW_Y, MotionConfig, sequence_flows, warp, warp_state
from methods.ssdd.networks import NetConfig
from methods.ssdd.prefilter import PrefilterConfig
from methods.ssdd.train import flows

K = Intrinsics(64, 48, 60.0, 60.0, 31.5, 23.5)
SPEED = 3                                      # pixels per frame to the right


def _bilinear(img, x, y):
    """Direct bilinear sample of ``img`` (h, w) at (x, y), coordinates clamped to the image (border)."""
    h, w = img.shape
    x, y = min(max(x, 0.0), w - 1.0), min(max(y, 0.0), h - 1.0)
    x0, y0 = min(int(np.floor(x)), w - 2), min(int(np.floor(y)), h - 2)
    fx, fy = x - x0, y - y0
    return ((1 - fx) * (1 - fy) * img[y0, x0] + fx * (1 - fy) * img[y0, x0 + 1]
            + (1 - fx) * fy * img[y0 + 1, x0] + fx * fy * img[y0 + 1, x0 + 1])


def test_warp_samples_at_the_flow_against_a_direct_loop_at_full_and_half_resolution():
    g = torch.Generator().manual_seed(0)
    x = torch.rand(2, 3, 6, 8, generator=g, dtype=torch.float64)
    flow = 3.0 * torch.randn(2, 2, 6, 8, generator=g, dtype=torch.float64)
    got = warp(x, flow).numpy()
    for b, c, i, j in np.ndindex(got.shape):
        want = _bilinear(x[b, c].numpy(), j + flow[b, 0, i, j].item(), i + flow[b, 1, i, j].item())
        assert abs(got[b, c, i, j] - want) < 1e-9
    # a level at half resolution: the flow averaged over each 2x2 block and halved
    half = torch.rand(2, 1, 3, 4, generator=g, dtype=torch.float64)
    got = warp_state({1: (half, 2 * half)}, flow)[1]
    for b, i, j in np.ndindex(2, 3, 4):
        f = flow[b, :, 2 * i:2 * i + 2, 2 * j:2 * j + 2].mean(dim=(1, 2)).numpy() / 2
        want = _bilinear(half[b, 0].numpy(), j + f[0], i + f[1])
        assert abs(got[0][b, 0, i, j] - want) < 1e-9 and abs(got[1][b, 0, i, j] - 2 * want) < 1e-9
    assert torch.allclose(warp(x, torch.zeros_like(flow)), x, rtol=0, atol=1e-12)


def _moving_scene(root, *, frames=5, seed=0):
    """A textured square moving SPEED px/frame to the right over a textured wall, in depth and colour."""
    rng = np.random.default_rng(seed)
    wall_tex = rng.integers(0, 256, (K.height, K.width + 64, 3)).astype(np.uint8)
    sq_tex = rng.integers(0, 256, (20, 20, 3)).astype(np.uint8)
    meta = {"name": root.name, "lq_intrinsics": K.to_dict(), "time_shift_us": 0, "T_lq_hq": np.eye(4).tolist()}
    with AlignedDatasetWriter(root, meta) as w:
        for i in range(frames):
            x0 = 8 + SPEED * i
            color = wall_tex[:, :K.width].copy()
            color[14:34, x0:x0 + 20] = sq_tex
            truth = np.full((K.height, K.width), 2.5, np.float32)
            truth[14:34, x0:x0 + 20] = 1.5
            lq = (truth + rng.normal(0, 0.01, truth.shape)).astype(np.float32)
            ref = (truth + rng.normal(0, 0.001, truth.shape)).astype(np.float32)
            w.add_frame(lq, ref, lq_color=color, truth=truth, lq_frame=i, hq_frame=i, lq_timestamp_us=i * 33_333)
    return AlignedDataset(root)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return _moving_scene(tmp_path_factory.mktemp("motion") / "scene")


@pytest.mark.parametrize("kind", ["color", "depth"])
def test_the_backward_flow_finds_where_the_moving_square_was(scene, kind):
    cfg = MotionConfig(kind=kind)
    images = [scene.lq_color(i) if kind == "color" else scene.lq_depth(i) for i in range(len(scene))]
    f = sequence_flows(images, cfg)
    assert f.shape == (len(scene), 2, K.height, K.width) and not f[0].any()
    inside = f[2][:, 18:30, 8 + 2 * SPEED + 4:8 + 2 * SPEED + 16]      # the square's interior in frame 2
    assert abs(np.median(inside[0]) + SPEED) < 0.5 and abs(np.median(inside[1])) < 0.5


def test_training_flows_stay_registered_under_crops_and_flips(scene):
    """A flipped sample's flow is the unflipped one mirrored with its x component negated (a direct formula)."""
    extra = flows([scene], MotionConfig(kind="color"))
    full = np.stack([extra[FLOW_X][scene.checksum], extra[FLOW_Y][scene.checksum]], axis=1)
    seen = set()
    for k in range(16):
        s = AlignedSamples([scene], sequence_length=3, crop=24, flip=True, seed=k, extra=extra)[1]
        t0 = int(s["index"][1])
        fl = batch_flow({key: v[None] for key, v in s.items()})[0].numpy()         # (T, 2, 24, 24)
        x0 = int(round(K.cx - s["camera"][2].item())) if not s["flip"] else int(round(s["camera"][2].item() - (23 - K.cx)))
        y0 = int(round(K.cy - s["camera"][3].item()))
        want = full[t0:t0 + 3, :, y0:y0 + 24, x0:x0 + 24]
        if s["flip"]:
            want = want[..., ::-1] * np.array([-1.0, 1.0], np.float32)[None, :, None, None]
        np.testing.assert_array_equal(fl, want)
        seen.add(bool(s["flip"]))
    assert seen == {False, True}


def _weights(path, motion: MotionConfig, *, pre: str = "none"):
    cfg = SSDDConfig(level1=Level1Config(model=NetConfig(width=4, levels=2), data=DataConfig(depth_scale_m=0.1),
                                         prefilter=PrefilterConfig(kind=pre)),
                     level2=Level2Config(model=NetConfig(width=4, levels=2, recurrent=[-1, 0]),
                                         data=DataConfig(depth_scale_m=0.1, sequence_length=2),
                                         centre="sequence", motion=motion))
    torch.manual_seed(0)
    l1, l2 = build_level1(cfg.level1), build_level2(cfg.level2)
    with torch.no_grad():
        l2.unet.head.weight.mul_(100.0)                    # a visible correction
    tensors = {**{f"level1/{k}": v for k, v in l1.state_dict().items()},
               **{f"level2/{k}": v for k, v in l2.state_dict().items()}}
    save_tensors(path, tensors, kind="weights", meta={"method": "ssdd_lstm", "config": to_dict(cfg),
                                                      "training": {"datasets": []}})
    return str(path), cfg, l1.eval(), l2.eval()


@pytest.mark.parametrize("motion", [MotionConfig(kind="color", previous="output"),
                                    MotionConfig(kind="depth", previous="level1", warp_state=False),
                                    MotionConfig(kind="color", previous="none")])
def test_streaming_inference_equals_trainings_sequence_pass_with_motion(scene, tmp_path, motion):
    """``ssdd_lstm`` frame by frame (flow found per frame, state and previous depth carried) equals the
    pass training makes over the whole sequence (:func:`flows` precomputed, :func:`level2_depth`); and
    the motion changes the output (the flow is used)."""
    path, cfg, l1, l2 = _weights(tmp_path / "w.safetensors", motion)
    method = get("ssdd_lstm", weights=path, fill_holes=True)
    assert method.uses_color == (motion.kind == "color")
    frames = [FrameInput(i, scene.lq_depth(i), color=scene.lq_color(i)) for i in range(len(scene))]
    streamed = np.stack(list(method.denoise_sequence(iter(frames))))
    extra = flows([scene], motion)
    fl = torch.from_numpy(np.stack([extra[FLOW_X][scene.checksum], extra[FLOW_Y][scene.checksum]], 1))[None]
    depth = torch.from_numpy(np.stack([f.depth for f in frames]))[None, :, None]
    with torch.no_grad():
        level1 = level1_depth(l1, depth, None, cfg.level1.data)
        seq = level2_depth(l2, level1, depth, None, cfg.level2.data, sequence_centre=True, flow=fl, motion=motion)
        still = level2_depth(l2, level1, depth, None, cfg.level2.data, sequence_centre=True,
                             flow=torch.zeros_like(fl), motion=motion)
    np.testing.assert_allclose(streamed, seq[0, :, 0].numpy(), rtol=0, atol=1e-5)
    assert (seq[0, 1:] - still[0, 1:]).abs().max().item() > 1e-4
    assert torch.equal(seq[0, 0], still[0, 0])             # the first frame has no motion


def test_the_leaderboard_config_column_names_the_options_not_in_the_paper(tmp_path):
    plain, *_ = _weights(tmp_path / "plain.safetensors", MotionConfig())
    ours, *_ = _weights(tmp_path / "ours.safetensors", MotionConfig(kind="color"), pre="bilateral")
    for name in ("ssdd_unet", "ssdd_lstm"):
        assert "not_in_paper" not in get(name, weights=plain).provenance()
    assert get("ssdd_unet", weights=ours).provenance()["not_in_paper"] == [
        "level1.prefilter.kind = 'bilateral'", "level2.motion.kind = 'color'"]
    column = _not_in_paper(get("ssdd_lstm", weights=ours).provenance())
    assert "not in the paper: `level1.prefilter.kind = 'bilateral'`, `level2.motion.kind = 'color'`" in column


def test_the_motion_config_is_checked():
    for bad in ({"kind": "optical"}, {"previous": "hq"}, {"flow_scale": 0.0}):
        with pytest.raises(ConfigError, match="motion"):
            from_dict(SSDDConfig, {"level2": {"motion": bad}}, where="c.toml")
    assert from_dict(SSDDConfig, {"level2": {"motion": {"kind": "depth"}}}, where="c.toml").level2.motion.kind == "depth"


def test_training_with_motion_runs_end_to_end_and_names_it(tmp_path):
    """``methods train ssdd_lstm`` with ``[level2.motion]`` (flows from the LQ depth: these datasets have no
    colour, which ``kind = "color"`` refuses in one line), then ``ssdd_lstm`` scores a held-out dataset."""
    from methods.errors import TrainingError
    from methods.nn.train import train_method
    from tests.methods.nn.helpers import make_manifest, write_test_config

    manifest = make_manifest(tmp_path / "corpus", {"a": "train", "b": "train", "c": "validation", "d": "test"}, frames=4)
    base = write_test_config(tmp_path / "c.toml", epochs=1).read_text()
    for kind in ("color", "depth"):
        (tmp_path / f"{kind}.toml").write_text(base + f'[level2.motion]\nkind = "{kind}"\n')
    with pytest.raises(TrainingError, match="no LQ colour"):
        train_method("ssdd_lstm", dataset=manifest, config=tmp_path / "color.toml", out=tmp_path / "bad",
                     device="cpu", progress=False)
    train_method("ssdd_lstm", dataset=manifest, config=tmp_path / "depth.toml", out=tmp_path / "run", device="cpu",
                 progress=False)
    method = get("ssdd_lstm", weights=str(tmp_path / "run" / "ssdd_lstm.safetensors"))
    assert method.provenance()["not_in_paper"] == ["level2.motion.kind = 'depth'"] and not method.uses_color
    test = AlignedDataset(tmp_path / "corpus" / "d")
    out = list(method.denoise_sequence(FrameInput(i, test.lq_depth(i)) for i in range(len(test))))
    assert all(np.isfinite(o[np.isfinite(test.lq_depth(i))]).all() for i, o in enumerate(out))
