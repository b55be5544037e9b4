"""Simultaneous multi-view samples for DDD's self-supervision, from the suite's multi-view alignment.

``depthbench align`` on a multi-view session (``multiview4`` / ``multiview4-hq`` rigs) writes
``ALIGNED/rig.json`` (every sensor's depth camera in one rig frame, ``T_rig_sensor``, fitted from
colour features: **calibrated, never the simulator's truth**) and one aligned dataset per view
(``ALIGNED/<view>/``). Each view's rows are paired with frames of the rig's reference sensor
(``hq_frame``; the reference view itself is paired with another view and keyed by its own
``lq_frame``), so rows of different views with the same reference frame were taken at the same
instant (within half a frame period): one **sample** is such a set of one frame per view.

A sample (float32 tensors, ``V`` views, optional ``downsample`` by 2 or 4 by hole-aware averaging with
the intrinsics scaled to match):

==========  ==============  ===============================================================
``depth``   (V, 1, h, w)    the view's LQ depth, metres, 0 = no measurement
``valid``   (V, 1, h, w)    1 where ``depth`` is measured
``color``   (V, 3, h, w)    the view's colour registered to its depth image, RGB in [0, 1]
``camera``  (V, 4)          ``fx, fy, cx, cy`` of the depth image, pixels
``T_rig``   (V, 4, 4)       ``T_rig_view``: view's depth camera -> rig frame, metres
``foreground``  (V, 1, h, w)  only with ``foreground=True``: 1 where the view's depth is clearly in
                            front of that view's own background (see below)
==========  ==============  ===============================================================

``foreground=True`` (the ``loss.foreground_weight`` option of :mod:`methods.ddd.model`): per view,
the background is a high percentile of that view's own depth over (up to) 40 frames of its session
(:func:`align.roi.background_depth`), and the foreground of a frame its pixels clearly in front of it
(:func:`align.roi.foreground_mask`, the same rule as the alignment's region of interest M_r, but from
the view's own LQ depth, at the training resolution). Moving people and balloons are found; a
person who stands still for most of the session is background.

Only the views' own measurements are read: never ``truth_depth``, and not the HQ reference
(DDD is self-supervised; the reference only served the calibration).

**Time.** Rows are matched through each view's fitted time shift: a view's row is keyed by the
reference frame the alignment paired it with, at that shift (eq. 28), so one sample's views are
within half a frame period of one instant when the shifts are right. Without hardware sync the shift
between two views 1-1.5 m apart is often unobservable from colour features (few moving features
match across the baseline); the multi-view alignment then finds it from the depth of what moves,
given the calibrated rig (:mod:`align.view_sync`; ``time_model.kind = "depth"`` in aligned.json).
With the old placeholder of 0 a sample's views on the demo's corpus (seed 2001) were 25-47 ms apart
in scene time (truth, diagnosis only), i.e. the walking people 25-47 mm apart between views, and DDD
did not beat raw on the people (issue 11, session 7). :func:`rig_groups` still warns when a view's
shift is a placeholder (neither colour nor depth determined it).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from align.dataset import AlignedDataset
from align.roi import background_depth, foreground_mask
from capture.camera import Transform
from depthbench.fsutil import read_json
from methods.errors import TrainingError

log = logging.getLogger(__name__)

RIG_JSON = "rig.json"
BACKGROUND_FRAMES = 40


@dataclass
class RigGroup:
    """The aligned datasets of one multi-view session and their calibrated rig."""

    root: Path
    views: list[AlignedDataset]
    T_rig: list[np.ndarray]
    rows: list[list[int]]  # per sample, the row of each view


def _key(ds: AlignedDataset, row: dict, reference: str) -> int:
    return int(row["lq_frame"] if ds.meta.get("lq_sensor") == reference else row["hq_frame"])


def rig_groups(datasets: list[AlignedDataset], *, min_views: int = 2) -> list[RigGroup]:
    """Group per-view aligned datasets by their multi-view folder and match simultaneous rows.

    Datasets without ``rig.json`` beside them are an error (DDD needs calibrated views).
    """
    by_root: dict[Path, list[AlignedDataset]] = {}
    for ds in datasets:
        root = ds.root.resolve().parent
        if not (root / RIG_JSON).is_file():
            raise TrainingError(f"{ds.root}: not a view of a multi-view alignment (no {RIG_JSON} beside it); "
                                "DDD trains on multi-view sessions aligned by 'depthbench align'")
        by_root.setdefault(root, []).append(ds)
    groups = []
    for root, views in by_root.items():
        rig = read_json(root / RIG_JSON, error=TrainingError, missing="")
        views = sorted(views, key=lambda d: d.meta.get("lq_sensor", ""))
        if len(views) < min_views:
            raise TrainingError(f"{root}: {len(views)} view(s) in the manifest, DDD needs at least {min_views}")
        try:
            T = [Transform.from_list(rig["T_rig_sensor"][v.meta["lq_sensor"]]).matrix.astype(np.float32) for v in views]
        except (KeyError, TypeError, ValueError) as exc:
            raise TrainingError(f"{root / RIG_JSON}: no usable T_rig_sensor for every view ({exc})") from None
        ref = rig.get("reference")
        unsynced = [v.meta.get("lq_sensor", "?") for v in views if not v.meta.get("time_model", {}).get("observable", True)]
        if unsynced:
            log.warning("%s: the time shift of %s is unobservable (a placeholder): a sample's views may be a frame or "
                        "more apart in time, and what moves is then not photo-consistent across them",
                        root, ", ".join(unsynced))
        index = [{_key(v, r, ref): i for i, r in enumerate(v.rows)} for v in views]
        common = sorted(set.intersection(*(set(k) for k in index)))
        groups.append(RigGroup(root, views, T, [[ix[k] for ix in index] for k in common]))
    return groups


def downsample(depth: np.ndarray, color: np.ndarray, f: int) -> tuple[np.ndarray, np.ndarray]:
    """Divide the resolution by ``f``: depth by the mean of the measured pixels of each ``f x f``
    block (NaN where none), colour by the mean. Pixel centre ``(u, v)`` moves to ``((u - (f-1)/2) / f, ...)``."""
    h, w = depth.shape[0] // f * f, depth.shape[1] // f * f
    d = depth[:h, :w].reshape(h // f, f, w // f, f)
    ok = np.isfinite(d)
    n = ok.sum(axis=(1, 3))
    dm = np.where(n > 0, np.where(ok, d, 0).sum(axis=(1, 3)) / np.maximum(n, 1), np.nan).astype(np.float32)
    c = color[:h, :w].reshape(h // f, f, w // f, f, 3).mean(axis=(1, 3)).astype(np.float32)
    return dm, c


class MultiViewSamples(Dataset):
    """Simultaneous frames of calibrated views (see the module docstring); ``downsample`` 1, 2 or 4;
    ``foreground``: add each view's own foreground mask."""

    def __init__(self, groups: list[RigGroup], *, downsample: int = 1, preload: bool = True,
                 foreground: bool = False) -> None:
        if downsample not in (1, 2, 4):
            raise TrainingError(f"downsample must be 1, 2 or 4, got {downsample}")
        self.groups, self.downsample, self.preload, self.foreground = groups, downsample, preload, foreground
        self._backgrounds: dict[tuple[int, int], np.ndarray] = {}
        self.items = [(g, k) for g in range(len(groups)) for k in range(len(groups[g].rows))]
        if not self.items:
            raise TrainingError("no simultaneous multi-view frames to train on")
        self._cache: dict[tuple[int, int], dict] = {}

    def set_epoch(self, epoch: int) -> None:
        """No random augmentation (flips or crops would break the calibrated geometry)."""

    def __len__(self) -> int:
        return len(self.items)

    def _view(self, ds: AlignedDataset, row: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        depth = ds.lq_depth(row)
        color = ds.lq_color(row)
        color = np.zeros(depth.shape + (3,), np.float32) if color is None else color.astype(np.float32) / 255.0
        K = ds.lq_intrinsics
        cam = np.array([K.fx, K.fy, K.cx, K.cy], np.float32)
        f = self.downsample
        if f > 1:
            depth, color = downsample(depth, color, f)
            cam = np.array([K.fx / f, K.fy / f, (K.cx - (f - 1) / 2) / f, (K.cy - (f - 1) / 2) / f], np.float32)
        return depth, color, cam

    def _background(self, g: int, v: int) -> np.ndarray:
        """View ``v`` of group ``g``: its background depth from its own frames (module docstring)."""
        if (g, v) not in self._backgrounds:
            group = self.groups[g]
            rows = [r[v] for r in group.rows]
            pick = np.unique(np.linspace(0, len(rows) - 1, min(BACKGROUND_FRAMES, len(rows))).round().astype(int))
            self._backgrounds[(g, v)] = background_depth(np.stack([self._view(group.views[v], rows[i])[0] for i in pick]))
        return self._backgrounds[(g, v)]

    def __getitem__(self, k: int) -> dict[str, torch.Tensor]:
        if k in self._cache:
            return self._cache[k]
        g, s = self.items[k]
        group = self.groups[g]
        views = [self._view(ds, r) for ds, r in zip(group.views, group.rows[s])]
        depth = np.stack([v[0] for v in views])[:, None]
        valid = np.isfinite(depth) & (depth > 0)
        out = {"depth": torch.from_numpy(np.where(valid, depth, 0).astype(np.float32)),
               "valid": torch.from_numpy(valid.astype(np.float32)),
               "color": torch.from_numpy(np.stack([v[1] for v in views]).transpose(0, 3, 1, 2).copy()),
               "camera": torch.from_numpy(np.stack([v[2] for v in views])),
               "T_rig": torch.from_numpy(np.stack(group.T_rig))}
        if self.foreground:
            area = max(1, 100 // self.downsample ** 2)   # the alignment's 100 px at full resolution
            fg = np.stack([foreground_mask(v[0], self._background(g, i), min_area_px=area)
                           for i, v in enumerate(views)])[:, None]
            out["foreground"] = torch.from_numpy(fg.astype(np.float32))
        if self.preload:
            self._cache[k] = out
        return out
