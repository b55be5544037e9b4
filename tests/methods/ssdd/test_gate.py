"""The reference gate of SSDD's loss (methods.ssdd.gate, not in the paper): the gate against a direct
per-pixel formula, both levels' losses equal to eq. 32 on the gate's pixels, and a level 1 trained for
real that no longer learns a misplaced reference at a moving silhouette."""
import numpy as np
import pytest
import torch

from align.dataset import AlignedDataset, AlignedDatasetWriter
from methods.nn.config import ConfigError, from_dict
from methods.nn.manifest import manifest_entry, write_manifest
from methods.nn.train import train_method
from methods.registry import get
from methods.ssdd.config import Level1Config, Level2Config, SSDDConfig
from methods.ssdd.gate import STEREO_NOISE_Z2, GateConfig, reference_gate
from methods.ssdd.model import build_level1, build_level2, level1_depth, level1_loss, level2_depth, level2_loss
from methods.ssdd.networks import NetConfig
from tests.methods.nn.helpers import K_TINY


def test_the_gate_keeps_exactly_the_references_within_the_lq_noise_against_a_direct_formula():
    rng = np.random.default_rng(0)
    lq = rng.uniform(0.5, 4.0, (3, 1, 9, 11))
    ref = lq + rng.normal(0, 0.03, lq.shape) * lq
    lq[rng.random(lq.shape) < 0.1] = np.nan
    ref[rng.random(lq.shape) < 0.1] = np.nan
    cfg = GateConfig(sigmas=2.5, floor_m=0.004, noise_z2=0.003)
    got = reference_gate(torch.from_numpy(ref), torch.from_numpy(lq), cfg).numpy()
    for idx in np.ndindex(lq.shape):
        r, z = float(ref[idx]), float(lq[idx])
        want = bool(np.isfinite(r) and np.isfinite(z) and abs(r - z) <= 0.004 + 2.5 * 0.003 * z * z)
        assert got[idx] == want, idx
    assert 0.2 < got.mean() < 0.9                          # both outcomes occur
    assert reference_gate(torch.from_numpy(ref), torch.from_numpy(lq), GateConfig()).all()   # off: no gate
    assert abs(STEREO_NOISE_Z2 - 0.0024242) < 1e-6         # the simulated LQ sensor's z^2 s / (f B)


def test_the_gate_config_is_checked():
    for bad in ({"sigmas": -1.0}, {"floor_m": -0.001}, {"noise_z2": -1e-3}):
        with pytest.raises(ConfigError, match="gate"):
            from_dict(SSDDConfig, {"level2": {"gate": bad}}, where="c.toml")
    cfg = from_dict(SSDDConfig, {"level1": {"gate": {"sigmas": 3.0}}}, where="c.toml")
    assert cfg.level1.gate.enabled and not cfg.level2.gate.enabled


def _batch(rng, shape):
    lq = rng.uniform(1.0, 3.0, shape).astype(np.float32)
    ref = (lq + rng.normal(0, 0.01, shape)).astype(np.float32)
    far = rng.random(shape) < 0.3
    ref[far] += 0.5                                        # a misplaced reference: far outside the LQ noise
    lq[rng.random(shape) < 0.1] = np.nan
    ref[rng.random(shape) < 0.1] = np.nan
    roi = (rng.random(shape) < 0.8).astype(np.float32)
    t = lambda a: torch.from_numpy(a)  # noqa: E731
    return {"lq_depth": t(lq), "reference": t(ref), "roi": t(roi), "valid": t(np.isfinite(ref).astype(np.float32)),
            "color": None}, lq, ref, roi


@pytest.mark.parametrize("level", [1, 2])
def test_both_levels_losses_are_eq32_on_the_gates_pixels_against_a_direct_sum(level):
    """The loss with a gate = sum over ROI pixels with LQ depth, a reference and |ref - lq| within the gate of
    |pred - ref|, divided by the number of pixels (eq. 32's "mean"), from the same prediction."""
    torch.manual_seed(0)
    rng = np.random.default_rng(level)
    gate = GateConfig(sigmas=3.0, floor_m=0.02)
    net_cfg = NetConfig(width=4, levels=2, recurrent=[-1] if level == 2 else [])
    if level == 1:
        cfg = Level1Config(model=net_cfg)
        batch, lq, ref, roi = _batch(rng, (2, 1, 12, 16))
        net = build_level1(cfg)
        pred = level1_depth(net, batch["lq_depth"], None, cfg.data).detach().numpy()
        losses = [level1_loss(cfg.data, gate=g)(net, batch) for g in (gate, None)]
    else:
        cfg = Level2Config(model=net_cfg)
        batch, lq, ref, roi = _batch(rng, (2, 3, 1, 12, 16))
        batch["level1"] = torch.nan_to_num(batch["lq_depth"], nan=2.0)
        net = build_level2(cfg)
        pred = level2_depth(net, batch["level1"], batch["lq_depth"], None, cfg.data).detach().numpy()
        losses = [level2_loss(cfg.data, gate=g)(net, batch) for g in (gate, None)]
    keep = np.zeros(lq.shape, bool)
    total = 0.0
    for idx in np.ndindex(lq.shape):
        r, z = float(ref[idx]), float(lq[idx])
        if roi[idx] and np.isfinite(z) and np.isfinite(r) and abs(r - z) <= 0.02 + 3.0 * STEREO_NOISE_Z2 * z * z:
            keep[idx] = True
            total += abs(float(pred[idx]) - r)
    assert 0.3 < keep.sum() / roi.sum() < 0.8              # the misplaced references were dropped, the rest kept
    assert losses[0].item() == pytest.approx(total / lq.size, rel=1e-5)
    assert losses[1].item() > 1.5 * losses[0].item()       # ungated, the misplaced references dominate


# ------------------------------------------------------------------------- a level 1 trained for real
K = K_TINY
DISC_Z, WALL_Z = 1.2, 2.0


def _disc_dataset(root, *, seed, frames=6, misplaced=True):
    """A disc moving right over a wall; LQ = truth + 1 % noise. The reference is the truth, except that on the
    disc's leading rim (the 3 px that the disc entered since the previous frame) it is the wall, where a
    reference carried from an earlier instant would leave it: a misplaced moving silhouette."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:K.height, 0:K.width].astype(np.float32)
    meta = {"name": root.name, "lq_intrinsics": K.to_dict(), "time_shift_us": 0, "T_lq_hq": np.eye(4).tolist()}
    with AlignedDatasetWriter(root, meta) as w:
        for i in range(frames):
            cx, cy = 8 + 3 * i + 2 * seed, K.height / 2
            disc = (u - cx) ** 2 + (v - cy) ** 2 < 81
            before = (u - cx + 3) ** 2 + (v - cy) ** 2 < 81
            truth = np.where(disc, DISC_Z, WALL_Z).astype(np.float32)
            lq = (truth * (1 + 0.01 * rng.normal(size=truth.shape))).astype(np.float32)
            ref = (truth + rng.normal(0, 0.001, truth.shape)).astype(np.float32)
            if misplaced:
                ref[disc & ~before] = WALL_Z
            w.add_frame(lq, ref, roi=np.ones(truth.shape, bool), truth=truth, lq_frame=i, hq_frame=i,
                        lq_timestamp_us=i * 33_333)
    return root


CONFIG = """\
[level1.model]
width = 8
levels = 2
[level1.data]
crop = 32
flip = false
roi_crop = 0.8
depth_scale_m = 0.1
validation_stride = 3
[level1.optim]
epochs = 6
batch_size = 8
samples_per_epoch = 96
lr = 3e-3
"""


def test_with_the_gate_level_1_stops_learning_a_misplaced_moving_silhouette(tmp_path):
    """Trained on references that put the disc's leading rim at the wall, the ungated level 1 moves the rim
    towards the wall (it cannot tell from one frame where the reference will be wrong, but the rim's
    pixels share a look); with ``[level1.gate]`` those references are out of the loss (0.8 m from the LQ
    depth) and the rim keeps the disc's depth. Scored against the truth of a held-out sequence."""
    entries = []
    for k, split in enumerate(["train", "train", "train", "validation"]):
        entries.append(manifest_entry(AlignedDataset(_disc_dataset(tmp_path / f"s{k}", seed=k)), root=tmp_path,
                                      split=split))
    manifest = write_manifest(tmp_path / "training.json", name="disc", entries=entries)
    held = AlignedDataset(_disc_dataset(tmp_path / "held", seed=5, misplaced=False))
    (tmp_path / "plain.toml").write_text(CONFIG)
    (tmp_path / "gated.toml").write_text(CONFIG + "[level1.gate]\nsigmas = 3.0\nnoise_z2 = 0.01\n")
    rim_mse = {}
    for name in ("plain", "gated"):
        train_method("ssdd_unet", dataset=manifest, config=tmp_path / f"{name}.toml", out=tmp_path / name,
                     device="cpu", progress=False)
        net = get("ssdd_unet", weights=str(tmp_path / name / "ssdd_unet.safetensors"), fill_holes=True)
        err = []
        for i in range(1, len(held)):
            cx = 8 + 3 * i + 10
            v, u = np.mgrid[0:K.height, 0:K.width]
            rim = ((u - cx) ** 2 + (v - K.height / 2) ** 2 < 81) & ((u - cx + 3) ** 2 + (v - K.height / 2) ** 2 >= 81)
            out = net.denoise(held.lq_depth(i))
            err.append(np.mean((out[rim] - held.truth(i)[rim]) ** 2))
        rim_mse[name] = float(np.mean(err))
    raw = float(np.mean((0.01 * DISC_Z) ** 2))
    assert rim_mse["gated"] < 0.25 * rim_mse["plain"], rim_mse
    assert rim_mse["gated"] < 4 * raw, (rim_mse, raw)     # near the disc's depth, not pulled to the wall
    assert get("ssdd_unet", weights=str(tmp_path / "gated" / "ssdd_unet.safetensors")).provenance()[
        "not_in_paper"] == ["level1.gate.sigmas = 3.0"]
