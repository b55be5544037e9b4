"""One benchmark task: a run of consecutive frames of one aligned dataset, every method that still needs them.

A task is a chunk of :func:`methods.run.plan_chunks`: one frame for frame methods (the usual
case: every frame method of the run shares the task, so the frame is read and its reference planes
are fitted once), a batch for batched methods, or a sequence chunk (with its warm-up frames) for
sequence methods. The methods are fed through :class:`methods.run.FrameRunner`, the path
``depthbench methods run`` takes, so a frame is treated the same way in both (an empty frame is
scored as an all-NaN prediction, a frame lacking colour for a colour method gets NaN metrics, a
frame a method refuses stops the run with :class:`methods.errors.FrameRejectedError`).

The task runs in whatever process the executor chose (this one, a local process pool, a Dask
worker) and returns plain rows per (method key, frame); it writes nothing.
"""
from __future__ import annotations

import logging
import sys
import warnings
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import pandas as pd

from align.dataset import AlignedDataset, AlignedFrame
from bench.errors import BenchError
from bench.masks import interior_strata, truth_strata
from bench.metrics import BINNED, UNITS, MetricConfig, fit_reference_planes, frame_metrics, moving_mask
from bench.results import SCHEMA_VERSION
from methods.base import FrameInput, MethodNeeds
from methods.run import DenoisedFrame, FrameRunner, read_input

log = logging.getLogger(__name__)

#: the references the HQ sensor is scored against: the truth on the HQ reference's pixels, and away from its depth
#: edges (:mod:`bench.masks`)
HQ_SENSOR_REFERENCES = ("truth", "truth_interior")


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
    needs = MethodNeeds()

    def describe(self) -> dict:
        return {"name": self.name, "version": self.version, "key": self.key, "learned": False,
                "description": self.description}


@dataclass(frozen=True)
class FrameTask:
    """What a worker needs for one chunk of one dataset.

    ``methods`` are Denoiser instances (or :class:`HQSensor`) sharing one chunk plan; ``frames`` are
    scored in order after the ``warmup`` frames are fed (sequence methods); ``cached`` holds the
    ``(method key, frame)`` results already in the cache (computed for the state, not scored);
    ``preview`` is the frame whose denoised depth is returned for the qualitative figure.
    """

    dataset_root: str
    dataset_checksum: str
    dataset_name: str
    sequence: str
    frames: tuple[int, ...]
    methods: tuple
    config: MetricConfig
    warmup: tuple[int, ...] = ()
    cached: frozenset = frozenset()
    preview: int | None = None
    threads: int | None = None     # CPU threads this task may use (metrics, numba kernels); None: library defaults

    @property
    def todo(self) -> list[tuple[str, int]]:
        """The (method key, frame) results this task computes."""
        return [(m.key, i) for i in self.frames for m in self.methods if (m.key, i) not in self.cached]


@dataclass
class FrameOutput:
    """Rows per (method key, frame), and the preview frame's denoised depth per method key."""

    rows: dict[tuple[str, int], pd.DataFrame] = field(default_factory=dict)
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


def _rows(method, task: FrameTask, frame: int, reference: str, metrics: dict, bins: list[dict]) -> list[tuple]:
    head = (SCHEMA_VERSION, method.name, str(method.version), method.key, task.dataset_name, task.dataset_checksum,
            task.sequence, frame, reference)
    rows = [head + (name, UNITS[name], np.nan, np.nan, float(metrics[name])) for name in UNITS]
    for b in bins:
        rows += [head + (name, UNITS[name], b["bin_lo_m"], b["bin_hi_m"], float(b[name])) for name in BINNED]
    return rows


_COLUMNS = ("schema_version", "method", "method_version", "method_key", "dataset", "dataset_checksum", "sequence",
            "frame", "reference", "metric", "unit", "bin_lo_m", "bin_hi_m", "value")


@dataclass
class _Scoring:
    """One frame held until every method's output for it is scored: the frame, its references and planes."""

    frame: AlignedFrame
    refs: dict
    planes: dict
    waiting: int
    moving: np.ndarray | None = None


class _TaskScorer:
    """Scores methods' outputs frame by frame into a :class:`FrameOutput`."""

    def __init__(self, task: FrameTask, ds: AlignedDataset, threads: int) -> None:
        self.task, self.ds, self.K, self.threads = task, ds, ds.lq_intrinsics, threads
        self.out = FrameOutput()
        self.held: dict[int, _Scoring] = {}

    def hold(self, fr: AlignedFrame, waiting: int) -> _Scoring:
        cfg = self.task.config
        refs = {"hq": fr.reference}
        if fr.truth is not None:   # the truth on the reference's pixels, and on the ROI pixels without one
            refs.update(truth_strata(fr.truth, fr.reference))
        refs.update(interior_strata(fr.reference, fr.truth))   # both away from the reference's depth edges
        planes = {name: fit_reference_planes(ref, self.K, roi=fr.roi, radius_m=cfg.radius_m,
                                             min_neighbors=cfg.min_neighbors, min_spread_ratio=cfg.min_spread_ratio,
                                             threads=self.threads)
                  for name, ref in refs.items()}
        held = _Scoring(frame=fr, refs=refs, planes=planes, waiting=waiting, moving=self._moving(fr))
        if waiting:      # released when the last awaited output is scored
            self.held[fr.index] = held
        return held

    def _moving(self, fr: AlignedFrame) -> np.ndarray | None:
        """The frame's moving pixels (:func:`bench.metrics.moving_mask`): from the truth where the dataset has
        one, else from the reference; None for the first frame."""
        if fr.index == 0:
            return None
        now, before = (fr.truth, self.ds.truth(fr.index - 1)) if fr.truth is not None else \
            (fr.reference, self.ds.reference(fr.index - 1))
        return moving_mask(now, before, threshold_m=self.task.config.moving_threshold_m)

    def score(self, method, frame: int, pred: np.ndarray | None, refs: dict | None = None) -> None:
        """Score ``pred`` (None: the frame lacks an input the method needs) against ``refs`` (default: all)."""
        held = self.held[frame]
        if (method.key, frame) not in self.task.cached:
            if held.planes["hq"].index.size == 0:     # no reference: scored as an all-NaN prediction
                pred = np.full(held.frame.lq_depth.shape, np.nan, np.float32)
            rows = []
            for name, ref in (held.refs if refs is None else refs).items():
                rows += _rows(method, self.task, frame, name, *self._metrics(pred, ref, held, name))
            df = pd.DataFrame.from_records(rows, columns=_COLUMNS)
            self.out.rows[(method.key, frame)] = df.astype({"schema_version": "int32", "frame": "int64"})
            if frame == self.task.preview:
                shape = held.frame.lq_depth.shape
                self.out.previews[method.key] = np.full(shape, np.nan, np.float32) if pred is None else \
                    np.asarray(pred, np.float32)
        held.waiting -= 1
        if held.waiting == 0:
            del self.held[frame]

    def _metrics(self, pred, ref, held: _Scoring, name: str) -> tuple[dict, list]:
        if pred is None:     # not applicable to this frame: every metric NaN, the reference still counted
            metrics = {k: np.nan for k in UNITS}
            metrics["n_reference"] = float(held.planes[name].index.size)
            return metrics, []
        return frame_metrics(pred, ref, self.K, roi=held.frame.roi, config=self.task.config,
                             planes=held.planes[name], threads=self.threads, moving=held.moving)


def compute_frame(task: FrameTask) -> FrameOutput:
    """Run and score every method of ``task`` on its frames (in order, after its warm-up frames).

    Returns a :class:`FrameOutput`; raises :class:`BenchError` or
    :class:`methods.errors.FrameRejectedError` naming the dataset and frame.
    """
    threads = _limit_threads(task.threads)
    ds = _open(task.dataset_root, task.dataset_checksum)
    scorer = _TaskScorer(task, ds, threads)
    methods = [m for m in task.methods if not isinstance(m, HQSensor)]
    hq_sensor = [m for m in task.methods if isinstance(m, HQSensor)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        runners = {m.key: FrameRunner(m, where=task.dataset_root, warmup=len(task.warmup)) for m in methods}
        for i in task.warmup:
            for m in methods:
                runners[m.key].push(read_input(ds, i, m))
        for i in task.frames:
            fr = ds.frame(i)
            sensors = hq_sensor if fr.truth is not None else []   # the reference itself, against the truth
            held = scorer.hold(fr, waiting=len(methods) + len(sensors))
            for m in sensors:
                scorer.score(m, i, fr.reference, refs={k: held.refs[k] for k in HQ_SENSOR_REFERENCES})
            frame = FrameInput(index=i, depth=fr.lq_depth, color=fr.lq_color, camera=ds.lq_intrinsics)
            for m in methods:
                _score_all(scorer, m, runners[m.key].push(frame))
        for m in methods:
            _score_all(scorer, m, runners[m.key].finish())
    return scorer.out


def _score_all(scorer: _TaskScorer, method, done: list[DenoisedFrame]) -> None:
    for d in done:
        scorer.score(method, d.index, d.depth)


def preview_inputs(ds: AlignedDataset, index: int) -> dict[str, np.ndarray]:
    """The arrays of the qualitative figure for frame ``index`` (LQ, reference, truth, ROI, colour, camera)."""
    fr = ds.frame(index)
    K = ds.lq_intrinsics
    return {"lq": fr.lq_depth, "reference": fr.reference, "truth": fr.truth, "roi": fr.roi, "color": fr.lq_color,
            "intrinsics": np.array([K.width, K.height, K.fx, K.fy, K.cx, K.cy], np.float64),
            "frame": np.array(index), "dataset": np.array(ds.name)}
