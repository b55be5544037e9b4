"""DDD trained for real through ``methods train`` on a small synthetic calibrated multi-view rig (three
cameras side by side before a textured wall and a moving disc; LQ = truth + 2 % noise + holes, the rig
in ``rig.json`` as the multi-view alignment writes it): simultaneous views are grouped, the splatting
loss trains the network, and it beats the raw depth against truth on a held-out rig session."""
from __future__ import annotations

import json

import numpy as np

from align.dataset import AlignedDataset, AlignedDatasetWriter
from capture.camera import Intrinsics, Transform
from methods.ddd.multiview import MultiViewSamples, rig_groups
from methods.nn.manifest import manifest_entry, write_manifest
from methods.nn.train import train_method
from methods.registry import get

K = Intrinsics(48, 40, 45.0, 45.0, 23.5, 19.5)
X = (-0.08, 0.0, 0.08)


def _rig_session(root, *, seed: int, frames: int = 5, observable: bool = True):
    """Three views; returns the per-view dataset folders (``root/view<k>``) and writes ``root/rig.json``."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:K.height, 0:K.width].astype(np.float64)
    rx, ry = (u - K.cx) / K.fx, (v - K.cy) / K.fy
    writers = {}
    for k, x0 in enumerate(X):
        meta = {"name": f"rig{seed}.view{k}", "lq_sensor": f"view{k}", "hq_sensor": "hq", "lq_intrinsics": K.to_dict(),
                "time_shift_us": 0, "T_lq_hq": np.eye(4).tolist(), "multiview": True, "rig_reference": "hq",
                "time_model": {"observable": observable or k == 0}}
        writers[k] = AlignedDatasetWriter(root / f"view{k}", meta)
    for i in range(frames):
        cx = -0.2 + 0.1 * i + 0.05 * seed
        for k, x0 in enumerate(X):
            disc = (x0 + 1.4 * rx - cx) ** 2 + (1.4 * ry) ** 2 < 0.25 ** 2
            z = np.where(disc, 1.4, 2.5)
            wx, wy = x0 + z * rx, z * ry
            tex = 0.5 + 0.35 * np.sin(23 * wx + 3 * disc) * np.cos(19 * wy)
            color = (255 * np.clip(np.stack([tex, 1 - tex, 0.5 + 0.3 * np.sin(31 * wx)], -1), 0, 1)).astype(np.uint8)
            truth = z.astype(np.float32)
            lq = (truth * (1 + rng.normal(0, 0.02, truth.shape))).astype(np.float32)
            lq[rng.random(truth.shape) < 0.03] = np.nan
            writers[k].add_frame(lq, truth, lq_color=color, roi=np.ones(truth.shape, bool), truth=truth,
                                 lq_frame=100 + i, hq_frame=i, lq_timestamp_us=i * 33_333)
    for w in writers.values():
        w.close()
    rig = {"format": "depthbench.rig", "reference": "hq",
           "T_rig_sensor": {f"view{k}": Transform.from_rt(np.eye(3), [x0, 0, 0]).to_list() for k, x0 in enumerate(X)}}
    (root / "rig.json").write_text(json.dumps(rig))
    return [root / f"view{k}" for k in range(3)]


CONFIG = """[model]
width = 4
[loss]
z_max_m = 3.0
[optim]
epochs = 6
batch_size = 2
samples_per_epoch = 10
lr = 3e-3
seed = 0
"""


def _held_out_mae_mm(run, folder) -> dict[str, float]:
    """MAE (mm) against truth of the raw depth and of ``run``'s DDD on a held-out rig session's view 1."""
    held = AlignedDataset(_rig_session(folder, seed=3, frames=3)[1])
    methods = {"raw": get("raw"), "ddd": get("ddd", weights=str(run.weights["ddd"]))}
    err = {name: [] for name in methods}
    for i in range(len(held)):
        f = held.frame(i)
        ok = np.isfinite(f.lq_depth)
        for name, m in methods.items():
            err[name].append(np.abs(m.denoise(f.lq_depth, f.lq_color, K) - f.truth)[ok])
    return {k: 1000 * float(np.concatenate(v).mean()) for k, v in err.items()}


def test_ddd_groups_simultaneous_views_trains_and_beats_raw(tmp_path):
    corpus = tmp_path / "corpus"
    train = [AlignedDataset(p) for p in _rig_session(corpus / "a", seed=0, frames=6)]
    groups = rig_groups(train)
    assert len(groups) == 1 and len(groups[0].rows) == 6
    sample = MultiViewSamples(groups)[2]
    assert sample["depth"].shape == (3, 1, 40, 48) and sample["T_rig"].shape == (3, 4, 4)
    assert abs(float(sample["T_rig"][2, 0, 3]) - X[2]) < 1e-6 and float(sample["camera"][0, 0]) == 45.0
    manifest = write_manifest(corpus / "mv.json", name="mv", entries=[manifest_entry(d, root=corpus, split="train")
                                                                         for d in train])
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(CONFIG)
    run = train_method("ddd", dataset=manifest, config=cfg, out=tmp_path / "run", device="cpu", progress=False)
    mae = _held_out_mae_mm(run, tmp_path / "held")
    assert mae["ddd"] < mae["raw"], mae


def test_rig_groups_warn_when_a_views_time_shift_is_a_placeholder(tmp_path, caplog):
    quiet = [AlignedDataset(p) for p in _rig_session(tmp_path / "a", seed=0, frames=2)]
    with caplog.at_level("WARNING", logger="methods.ddd.multiview"):
        rig_groups(quiet)
    assert not caplog.records
    loud = [AlignedDataset(p) for p in _rig_session(tmp_path / "b", seed=0, frames=2, observable=False)]
    with caplog.at_level("WARNING", logger="methods.ddd.multiview"):
        groups = rig_groups(loud)
    assert len(groups[0].rows) == 2
    msg = " ".join(r.getMessage() for r in caplog.records)
    assert "view1, view2" in msg and "unobservable" in msg and "view0" not in msg.split("shift of")[1].split("is")[0]


def test_ddd_tiny_config_trains_and_beats_raw(tmp_path):
    """The shipped ``tiny`` config as ``methods train ddd --config tiny`` runs it (warm start, then eq. 22 at
    the training resolution) on the synthetic rig: trained for real, it beats the raw depth against truth
    on a held-out rig session."""
    from methods.ddd.train import DDDConfig
    from methods.nn.config import load_config

    cfg, _ = load_config("tiny", DDDConfig, family="ddd")
    assert cfg.data.downsample == 1 and cfg.warmup.steps > 0   # what the demo trains
    corpus = tmp_path / "corpus"
    train = [AlignedDataset(p) for p in _rig_session(corpus / "a", seed=0, frames=6)]
    manifest = write_manifest(corpus / "mv.json", name="mv", entries=[manifest_entry(d, root=corpus, split="train")
                                                                         for d in train])
    run = train_method("ddd", dataset=manifest, config="tiny", out=tmp_path / "run", device="cpu", progress=False)
    mae = _held_out_mae_mm(run, tmp_path / "held")
    assert mae["ddd"] < mae["raw"], mae
