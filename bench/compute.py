"""One benchmark task: one frame of one aligned dataset, every method that still needs it.

The task reads the frame once, fits the reference planes once per reference (HQ, and truth when the
dataset is simulated), runs each method and scores it. It runs in whatever process the executor
chose (this one, a local process pool, a Dask worker) and returns plain rows; it writes nothing.
"""
from __future__ import annotations

import logging
import sys
import warnings
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import pandas as pd

from align.dataset import AlignedDataset
from bench.errors import BenchError, MethodOutputError, MethodRunError  # noqa: F401 (re-exported)
from bench.metrics import BINNED, UNITS, MetricConfig, fit_reference_planes, frame_metrics
from bench.results import SCHEMA_VERSION
from methods.base import Denoiser
from methods.errors import MethodError

log = logging.getLogger(__name__)


class HQSensor:
    """Pseudo-method: the warped HQ depth itself, scored against the simulator's truth.

    Shows how much of every method's measured error is the reference sensor's own error.
    Scored only where the dataset has truth; never a column of the HQ leaderboard.
    """

    name = "hq_sensor"
    version = "1"
    params: dict = {}
    learned = False
    description = "the HQ reference depth (warped onto the LQ image) against the simulator's truth"
    key = "hq_sensor@1()"


@dataclass(frozen=True)
class FrameTask:
    """What a worker needs for one frame. ``methods`` are Denoiser instances (or :class:`HQSensor`)."""

    dataset_root: str
    dataset_checksum: str
    dataset_name: str
    sequence: str
    frame: int
    methods: tuple
    config: MetricConfig
    preview: bool = False
    threads: int | None = None     # CPU threads this task may use (metrics, numba kernels); None: library defaults


@dataclass
class FrameOutput:
    """Rows per method key, and (for the preview frame) the denoised depth per method key."""

    frame: int
    rows: dict[str, pd.DataFrame] = field(default_factory=dict)
    previews: dict[str, np.ndarray] = field(default_factory=dict)


@lru_cache(maxsize=16)
def _open(root: str, checksum: str) -> AlignedDataset:
    ds = AlignedDataset(root)
    if ds.checksum != checksum:
        raise BenchError(f"{root}: dataset changed while the benchmark ran (checksum {ds.checksum[:12]}..., "
                         f"expected {checksum[:12]}...)")
    return ds


def _limit_threads(threads: int | None) -> int:
    """Cap the numba kernels of the methods at ``threads`` (this thread only); returns the metric threads.

    With several worker processes on one machine each gets its share of the cores, so N workers do
    not run N x cores threads.
    """
    if threads is None:
        return 1
    numba = sys.modules.get("numba")
    if numba is not None:
        try:
            numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
        except (ValueError, RuntimeError):   # pragma: no cover - a numba without threading layer
            pass
    return max(1, threads)


def _denoise(method: Denoiser, frame, K, task: FrameTask) -> np.ndarray | None:
    """The method's output, or None when the frame lacks an input the method needs (colour)."""
    lq = frame.lq_depth
    if getattr(method, "uses_color", False) and frame.lq_color is None:
        return None
    if not np.isfinite(lq).any():     # nothing to denoise: the method leaves every pixel empty
        return np.full(lq.shape, np.nan, np.float32)
    try:
        out = method.denoise(lq, frame.lq_color, K)
    except MethodError as exc:
        raise MethodRunError(f"{method.key} on {task.dataset_root} frame {task.frame}: {exc}") from None
    if not isinstance(out, np.ndarray) or out.shape != lq.shape:
        raise MethodOutputError(f"method {method.key} returned {getattr(out, 'shape', type(out).__name__)} for a "
                                f"{lq.shape} depth ({task.dataset_root}, frame {task.frame})")
    return out.astype(np.float32, copy=False)


def _rows(method, task: FrameTask, reference: str, metrics: dict, bins: list[dict]) -> list[tuple]:
    head = (SCHEMA_VERSION, method.name, str(method.version), method.key, task.dataset_name, task.dataset_checksum,
            task.sequence, task.frame, reference)
    rows = [head + (name, UNITS[name], np.nan, np.nan, float(metrics[name])) for name in UNITS]
    for b in bins:
        rows += [head + (name, UNITS[name], b["bin_lo_m"], b["bin_hi_m"], float(b[name])) for name in BINNED]
    return rows


_COLUMNS = ("schema_version", "method", "method_version", "method_key", "dataset", "dataset_checksum", "sequence",
            "frame", "reference", "metric", "unit", "bin_lo_m", "bin_hi_m", "value")


def compute_frame(task: FrameTask) -> FrameOutput:
    """Run and score every method of ``task`` on its frame.

    Returns a :class:`FrameOutput`; raises :class:`BenchError` (or the method's own error) naming
    the dataset and frame.
    """
    threads = _limit_threads(task.threads)
    ds = _open(task.dataset_root, task.dataset_checksum)
    fr = ds.frame(task.frame)
    K = ds.lq_intrinsics
    cfg = task.config
    refs = {"hq": fr.reference}
    if fr.truth is not None:
        refs["truth"] = fr.truth
    out = FrameOutput(task.frame)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        planes = {name: fit_reference_planes(ref, K, roi=fr.roi, radius_m=cfg.radius_m,
                                             min_neighbors=cfg.min_neighbors, min_spread_ratio=cfg.min_spread_ratio,
                                             threads=threads)
                  for name, ref in refs.items()}
        hq_empty = planes["hq"].index.size == 0
        for method in task.methods:
            if isinstance(method, HQSensor):
                if "truth" not in refs:
                    continue
                pred, scored = fr.reference, {"truth": refs["truth"]}
            else:
                scored = refs
                if hq_empty:   # no reference: nothing to score, no need to run the method
                    pred = np.full(fr.lq_depth.shape, np.nan, np.float32)
                else:
                    pred = _denoise(method, fr, K, task)
            rows = []
            for name, ref in scored.items():
                if pred is None:     # not applicable to this frame: every metric NaN, the reference still counted
                    metrics = {k: np.nan for k in UNITS}
                    metrics["n_reference"] = float(planes[name].index.size)
                    bins = []
                else:
                    metrics, bins = frame_metrics(pred, ref, K, roi=fr.roi, config=cfg, planes=planes[name],
                                                  threads=threads)
                rows += _rows(method, task, name, metrics, bins)
            if pred is None:
                pred = np.full(fr.lq_depth.shape, np.nan, np.float32)
            df = pd.DataFrame.from_records(rows, columns=_COLUMNS)
            out.rows[method.key] = df.astype({"schema_version": "int32", "frame": "int64"})
            if task.preview:
                out.previews[method.key] = np.asarray(pred, np.float32)
    return out


def preview_inputs(ds: AlignedDataset, index: int) -> dict[str, np.ndarray]:
    """The arrays of the qualitative figure for frame ``index`` (LQ, reference, truth, ROI, colour, camera)."""
    fr = ds.frame(index)
    K = ds.lq_intrinsics
    return {"lq": fr.lq_depth, "reference": fr.reference, "truth": fr.truth, "roi": fr.roi, "color": fr.lq_color,
            "intrinsics": np.array([K.width, K.height, K.fx, K.fy, K.cx, K.cy], np.float64),
            "frame": np.array(index), "dataset": np.array(ds.name)}
