"""Small synthetic aligned datasets and training manifests for the training tests (fast: no simulator)."""
from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

import numpy as np

from align.dataset import AlignedDatasetWriter
from capture.camera import Intrinsics
from methods.nn.manifest import manifest_entry, write_manifest
from align.dataset import AlignedDataset

K_TINY = Intrinsics(48, 40, 45.0, 45.0, 23.5, 19.5)


def coded_dataset(root: Path, *, name: str, frames: int = 5, K: Intrinsics = K_TINY, roi=None) -> Path:
    """Every layer encodes (x, y, frame) so a test can check that crops/flips keep layers registered.

    colour: R = x, G = y, B = frame; LQ depth = 1 + x mm + 10 y mm + 100 frame mm (metres, exact at
    0.1 mm); reference = LQ depth + 0.5 m, NaN where (x + y + frame) % 7 == 0; ROI = x even, or
    ``roi(x, y, frame)`` (bool arrays) when given.
    """
    v, u = np.mgrid[0:K.height, 0:K.width]
    meta = {"name": name, "lq_intrinsics": K.to_dict(), "time_shift_us": 0, "T_lq_hq": np.eye(4).tolist()}
    with AlignedDatasetWriter(root, meta) as w:
        for i in range(frames):
            depth = (1.0 + 0.001 * u + 0.01 * v + 0.1 * i).astype(np.float32)
            ref = (depth + 0.5).astype(np.float32)
            ref[(u + v + i) % 7 == 0] = np.nan
            col = np.stack([u, v, np.full_like(u, i)], axis=-1).astype(np.uint8)
            w.add_frame(depth, ref, lq_color=col, roi=(u % 2 == 0) if roi is None else roi(u, v, i), lq_frame=i, hq_frame=i, lq_timestamp_us=i * 33_333)
    return root


def scene_dataset(root: Path, *, name: str, frames: int = 6, K: Intrinsics = K_TINY, seed: int = 0,
                  speed_px: float = 2.0) -> Path:
    """A disc moving in front of a slanted wall; LQ = truth + noise + holes, reference = truth + 1 mm noise."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:K.height, 0:K.width].astype(np.float32)
    meta = {"name": name, "lq_intrinsics": K.to_dict(), "time_shift_us": 0, "T_lq_hq": np.eye(4).tolist()}
    with AlignedDatasetWriter(root, meta) as w:
        for i in range(frames):
            cx = 10 + speed_px * i + 4 * seed
            wall = 2.5 + 0.01 * u
            disc = (u - cx) ** 2 + (v - K.height / 2) ** 2 < 64
            truth = np.where(disc, 1.2, wall).astype(np.float32)
            lq = (truth + rng.normal(0, 0.02, truth.shape) * truth).astype(np.float32)
            lq[rng.random(truth.shape) < 0.03] = np.nan
            ref = (truth + rng.normal(0, 0.001, truth.shape)).astype(np.float32)
            ref[rng.random(truth.shape) < 0.05] = np.nan
            roi = np.ones(truth.shape, bool)
            roi[:, :3] = False
            w.add_frame(lq, ref, roi=roi, truth=truth, lq_frame=i, hq_frame=i, lq_timestamp_us=i * 33_333)
    return root


def make_manifest(root: Path, splits: dict[str, str], *, frames: int = 6, name: str = "synthetic") -> Path:
    """Scene datasets ``root/<name>`` with the given split each, and ``root/training.json``."""
    entries = []
    for k, (ds_name, split) in enumerate(splits.items()):
        scene_dataset(root / ds_name, name=ds_name, frames=frames, seed=k)
        entries.append(manifest_entry(AlignedDataset(root / ds_name), root=root, split=split))
    return write_manifest(root / "training.json", name=name, entries=entries)


TEST_CONFIG = """\
folds = 2
[level1.model]
width = 4
levels = 2
[level1.data]
crop = 32
[level1.optim]
epochs = {epochs}
batch_size = 4
samples_per_epoch = 8
lr = 3e-3
seed = {seed}
[level2.model]
width = 4
levels = 2
recurrent = [-1]
[level2.data]
crop = 32
sequence_length = 3
[level2.optim]
epochs = {epochs}
batch_size = 2
samples_per_epoch = 4
lr = 3e-3
"""


def write_test_config(path: Path, *, epochs: int = 2, seed: int = 0) -> Path:
    """A training config for tests: 4-channel, 2-level networks on 32-pixel crops, a few steps."""
    path.write_text(TEST_CONFIG.format(epochs=epochs, seed=seed))
    return path


@contextmanager
def torch_threads(n: int):
    """Run the block with ``n`` torch intra-op threads, then restore the caller's count (tests/methods runs on one:
    ``conftest.py``)."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)
