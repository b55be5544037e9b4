"""Synthetic aligned datasets and test-only methods for the bench tests (importable by worker processes)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from align.dataset import AlignedDatasetWriter
from capture.camera import Intrinsics
from methods.base import Denoiser

K_SMALL = Intrinsics(80, 60, 70.0, 70.0, 39.5, 29.5)


def scene_depth(K: Intrinsics, *, base: float = 1.2, seed: int = 0) -> np.ndarray:
    """A smooth slanted surface with a bump, float32 metres."""
    v, u = np.mgrid[0:K.height, 0:K.width]
    z = base + 0.004 * u + 0.002 * v + 0.05 * np.exp(-((u - 0.6 * K.width) ** 2 + (v - 0.5 * K.height) ** 2) / 60.0)
    return z.astype(np.float32)


def box_scene(i: int, *, step_m: float, K: Intrinsics = K_SMALL) -> tuple[np.ndarray, np.ndarray]:
    """Frame ``i`` of a near box moving 2 px per frame in front of :func:`scene_depth`'s wall at 1.5 m:
    ``(truth (H, W) float32 metres, box (H, W) bool)``, the box ``step_m`` nearer than the wall."""
    t = scene_depth(K, base=1.5)
    box = np.zeros(t.shape, bool)
    box[18:42, 22 + 2 * i:52 + 2 * i] = True
    t[box] -= np.float32(step_m)
    return t, box


def make_dataset(root: Path, *, name: str = "synth", sequence: str | None = None, frames: int = 3,
                 K: Intrinsics = K_SMALL, truth: bool = True, roi: bool = True, color: bool = True,
                 lq_noise: float = 0.004, hq_noise: float = 0.001, empty_reference: bool = False,
                 seed: int = 0) -> Path:
    """A tiny aligned dataset: noisy LQ, less noisy reference, optional truth/ROI/colour."""
    rng = np.random.default_rng(seed)
    meta = {"name": name, "lq_intrinsics": K.to_dict(), "time_shift_us": 0,
            "T_lq_hq": np.eye(4).tolist()}
    if sequence:
        meta["sequence"] = sequence
    with AlignedDatasetWriter(root, meta) as w:
        for i in range(frames):
            t = scene_depth(K, base=1.2 + 0.05 * i)
            lq = (t + rng.normal(0, lq_noise, t.shape)).astype(np.float32)
            lq[rng.random(t.shape) < 0.05] = np.nan
            ref = (t + rng.normal(0, hq_noise, t.shape)).astype(np.float32)
            ref[:5, :] = np.nan
            if empty_reference:
                ref[:] = np.nan
            m = np.zeros(t.shape, bool)
            m[5:-5, 8:-8] = True
            col = (rng.random(t.shape + (3,)) * 255).astype(np.uint8)
            w.add_frame(lq, ref, lq_color=col if color else None, roi=m if roi else None, truth=t if truth else None,
                        lq_frame=i, hq_frame=i, lq_timestamp_us=i * 33_333)
    return root


class Shift(Denoiser):
    """Test method: adds ``mm`` millimetres to every depth."""

    name = "test_shift"
    version = "1"
    defaults = {"mm": 5.0}

    def _denoise(self, depth, color, camera):
        return depth + np.float32(self.params["mm"] / 1000.0)


class ShiftV2(Shift):
    """The same method after a version bump."""

    version = "2"


class Smooth(Denoiser):
    """Test method: 3x3 mean of the valid neighbours (a crude denoiser)."""

    name = "test_smooth"
    version = "1"

    def _denoise(self, depth, color, camera):
        from scipy.ndimage import uniform_filter

        valid = np.isfinite(depth)
        z = np.where(valid, depth, 0).astype(np.float64)
        num = uniform_filter(z, 3, mode="nearest")
        den = uniform_filter(valid.astype(np.float64), 3, mode="nearest")
        with np.errstate(invalid="ignore", divide="ignore"):
            out = np.where(valid, num / den, np.nan)
        return out.astype(np.float32)
