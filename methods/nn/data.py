"""PyTorch datasets over aligned datasets: frames or short sequences, registered crops and flips.

A sample is a dict of float32 tensors, always with a time axis ``T`` (1 for single frames):

=================  ==============  ==========================================================
key                shape           meaning
=================  ==============  ==========================================================
``lq_depth``       (T, 1, h, w)    LQ depth, metres, NaN = no measurement
``color``          (T, 3, h, w)    LQ colour, RGB in [0, 1] (zeros when the dataset has none)
``reference``      (T, 1, h, w)    HQ depth warped onto the LQ image, metres, NaN = none
``roi``            (T, 1, h, w)    region of interest M_r of eq. 32, 0/1 (all 1 without ROI)
``valid``          (T, 1, h, w)    valid-reference mask M_NaN of eq. 32: ``isfinite(reference)``
``<extra>``        (T, 1, h, w)    any extra per-frame depth layer given to the dataset
                                   (e.g. out-of-fold level-1 predictions), metres, NaN = none
``has_color``      ()              1 when the dataset has colour
``flip``           ()              1 when the sample is flipped horizontally (a vector layer's x
                                   component, e.g. an optical flow, must then change sign)
``camera``         (4,)            LQ depth intrinsics of the crop as seen: ``fx, fy, cx', cy'`` in
                                   pixels, ``cx' = cx - x0``, ``cy' = cy - y0`` and, flipped,
                                   ``cx' = (w - 1) - cx'`` (distortion ignored)
``index``          (2,)            (dataset number, first frame) of the sample
=================  ==============  ==========================================================

A sequence is ``T`` consecutive rows of one aligned dataset (never across datasets). Crops
(square, ``crop`` pixels) and horizontal flips are drawn once per sample and applied identically to
every layer and every frame, so depth, colour, masks and frames stay registered. The draw depends
only on ``(seed, epoch, sample number)``: which process loads a sample does not change it (the basis
of the multi-process equality of :mod:`methods.nn.trainer`). The simulator's truth is never read:
training is supervised by the HQ reference only (SSDD's self-supervision).

Depth stays in metres here; networks normalise their inputs (:mod:`methods.nn.normalize`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch.utils.data import Dataset

from align.dataset import AlignedDataset
from methods.errors import TrainingError

LAYERS = ("lq_depth", "color", "reference", "roi", "valid")


@dataclass(frozen=True)
class Window:
    """Sample ``k``: ``length`` consecutive frames of dataset ``dataset`` from ``start``."""

    dataset: int
    start: int
    length: int


class _FrameCache:
    """Decoded frames of one aligned dataset (all of them with ``preload``, else none kept)."""

    def __init__(self, ds: AlignedDataset, *, keep: bool) -> None:
        self.ds = ds
        self.keep = keep
        self._frames: dict[int, dict] = {}
        shape = ds.lq_intrinsics.shape
        self.shape = shape
        self.has_color = any(r["lq_color_file"] for r in ds.rows)

    def frame(self, i: int) -> dict:
        if i in self._frames:
            return self._frames[i]
        h, w = self.shape
        color = self.ds.lq_color(i)
        roi = self.ds.roi(i)
        f = {"lq_depth": self.ds.lq_depth(i), "reference": self.ds.reference(i),
             "color": np.zeros((h, w, 3), np.uint8) if color is None else color,
             "roi": np.ones((h, w), bool) if roi is None else roi}
        if self.keep:
            self._frames[i] = f
        return f


def sample_rng(seed: int, epoch: int, k: int) -> np.random.Generator:
    """The random stream of sample ``k`` in ``epoch``: the same in every process."""
    return np.random.default_rng([int(seed), int(epoch), int(k)])


def crop_box(shape: tuple[int, int], crop: int, rng: np.random.Generator) -> tuple[int, int, int, int]:
    """A random ``crop``-pixel square inside ``shape`` (0 = the whole image): ``(y0, x0, h, w)``."""
    h, w = shape
    if crop <= 0:
        return 0, 0, h, w
    y0 = int(rng.integers(0, h - crop + 1))
    x0 = int(rng.integers(0, w - crop + 1))
    return y0, x0, crop, crop


def roi_crop_box(roi: np.ndarray, crop: int, rng: np.random.Generator) -> tuple[int, int, int, int] | None:
    """A ``crop``-pixel square centred (as far as the frame allows) on a random pixel of ``roi``
    ``(H, W)`` bool: ``(y0, x0, h, w)``; None when ``roi`` is empty or ``crop`` is 0."""
    ys, xs = np.nonzero(roi)
    if crop <= 0 or ys.size == 0:
        return None
    j = int(rng.integers(0, ys.size))
    h, w = roi.shape
    y0 = min(max(int(ys[j]) - crop // 2, 0), h - crop)
    x0 = min(max(int(xs[j]) - crop // 2, 0), w - crop)
    return y0, x0, crop, crop


def crop_camera(K, *, y0: int, x0: int, w: int, flip: bool) -> torch.Tensor:
    """Intrinsics ``(fx, fy, cx, cy)`` of a crop at ``(y0, x0)`` of width ``w``, mirrored when ``flip``."""
    cx, cy = K.cx - x0, K.cy - y0
    if flip:
        cx = (w - 1) - cx
    return torch.tensor([K.fx, K.fy, cx, cy], dtype=torch.float32)


class AlignedSamples(Dataset):
    """Samples (frames or sequences) of aligned datasets, with registered random crops and flips.

    Args:
        datasets: aligned datasets (one sequence each).
        sequence_length: frames per sample (``T``).
        crop: square crop side in pixels; 0 = whole frames (all datasets must then share a size).
        flip: random horizontal flips (probability 1/2).
        seed: fixes crops and flips with the epoch (:meth:`set_epoch`) and the sample number.
        preload: keep decoded frames in memory.
        extra: extra per-frame depth layers, ``{layer name: {dataset checksum: (F, H, W) float32 metres}}``.
        stride: distance between the first frames of consecutive samples of a dataset.
        roi_crop: probability that a crop is centred on a random ROI pixel of the sample's first
            frame instead of drawn uniformly (0: always uniform). Where the ROI covers a small part
            of the frame (people at a distance), uniform crops carry few loss pixels of eq. 32.
    """

    def __init__(self, datasets: list[AlignedDataset], *, sequence_length: int = 1, crop: int = 0, flip: bool = False,
                 seed: int = 0, preload: bool = False, extra: dict[str, dict[str, np.ndarray]] | None = None,
                 stride: int = 1, roi_crop: float = 0.0) -> None:
        if not datasets:
            raise TrainingError("no dataset to draw training samples from")
        self.caches = [_FrameCache(ds, keep=preload) for ds in datasets]
        self.sequence_length, self.crop, self.flip, self.seed = int(sequence_length), int(crop), bool(flip), int(seed)
        self.extra = extra or {}
        self.roi_crop = float(roi_crop)
        self.epoch = 0
        shapes = {c.shape for c in self.caches}
        for c in self.caches:
            if crop and (c.shape[0] < crop or c.shape[1] < crop):
                raise TrainingError(f"{c.ds.root}: frames are {c.shape[1]}x{c.shape[0]}, smaller than the crop {crop}")
            for name, layers in self.extra.items():
                arr = layers.get(c.ds.checksum)
                if arr is None or arr.shape != (len(c.ds),) + c.shape:
                    raise TrainingError(f"{c.ds.root}: extra layer {name!r} missing or not of shape "
                                        f"{(len(c.ds),) + c.shape}")
        if not crop and len(shapes) > 1:
            raise TrainingError(f"datasets of different frame sizes {sorted(shapes)} need a crop")
        self.windows = [Window(d, s, self.sequence_length) for d, c in enumerate(self.caches)
                        for s in range(0, len(c.ds) - self.sequence_length + 1, max(1, int(stride)))]
        if not self.windows:
            raise TrainingError(f"no dataset has {self.sequence_length} frames for one sequence")

    def set_epoch(self, epoch: int) -> None:
        """Draw the next epoch's crops and flips (call before each epoch, in every process)."""
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return len(self.windows)

    def __getitem__(self, k: int) -> dict[str, torch.Tensor]:
        win = self.windows[k]
        cache = self.caches[win.dataset]
        rng = sample_rng(self.seed, self.epoch, k)
        frames = [cache.frame(i) for i in range(win.start, win.start + win.length)]
        box = None
        if self.roi_crop > 0 and rng.random() < self.roi_crop:
            box = roi_crop_box(frames[0]["roi"], self.crop, rng)
        y0, x0, h, w = box or crop_box(cache.shape, self.crop, rng)
        flip = self.flip and bool(rng.integers(0, 2))

        def take(a: np.ndarray) -> np.ndarray:
            a = a[y0:y0 + h, x0:x0 + w]
            return a[:, ::-1] if flip else a

        depth = np.stack([take(f["lq_depth"]) for f in frames])[:, None]
        ref = np.stack([take(f["reference"]) for f in frames])[:, None]
        out = {"lq_depth": depth, "reference": ref,
               "color": np.stack([take(f["color"]) for f in frames]).transpose(0, 3, 1, 2).astype(np.float32) / 255.0,
               "roi": np.stack([take(f["roi"]) for f in frames])[:, None].astype(np.float32),
               "valid": np.isfinite(ref).astype(np.float32)}
        for name, layers in self.extra.items():
            arr = layers[cache.ds.checksum]
            out[name] = np.stack([take(arr[i]) for i in range(win.start, win.start + win.length)])[:, None]
        sample = {k2: torch.from_numpy(np.ascontiguousarray(v, dtype=np.float32)) for k2, v in out.items()}
        sample["has_color"] = torch.tensor(float(cache.has_color))
        sample["flip"] = torch.tensor(float(flip))
        sample["camera"] = crop_camera(cache.ds.lq_intrinsics, y0=y0, x0=x0, w=w, flip=flip)
        sample["index"] = torch.tensor([win.dataset, win.start])
        return sample
