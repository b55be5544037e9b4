"""Rendering frames in parallel: each worker process renders whole frames and encodes them.

Open3D holds the GIL while it casts, so threads cannot overlap the casts with the numpy and
encoding work; separate processes can (:mod:`capture.sim.worker`). Every frame's randomness is seeded by
``(seed, sensor, frame number)`` alone, so the bytes do not depend on the number of workers or
on which worker rendered which frame. The main process only writes files and index rows, in
scene-time order.
"""
from __future__ import annotations

import time
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from capture.sim.effects import SensorEffects
from capture.sim.kernels import depth_counts
from capture.sim.output import TRUTH_DEPTH_UNIT_M, Plan
from capture.sim.render import Renderer
from capture.sim.scene import build_scene
from capture.sim.sensors import SensorCameras, render_frame
from depthbench import frames as codec
from depthbench.fsutil import sha256_bytes

#: One frame to render: (scene time µs, sensor order, sensor id, index in its schedule).
Event = tuple[int, int, str, int]


@dataclass
class EncodedFrame:
    """A rendered frame, encoded: ``files`` maps ``depth``/``color``/``truth`` to
    ``(bytes, extension, sha256)``;
    ``stage_s``: seconds spent per stage on it."""

    sensor: str
    index: int
    frame_number: int
    files: dict[str, tuple[bytes, str, str]]
    stage_s: dict[str, float]


class _StageTimings(dict):
    """Per-stage seconds (``time.perf_counter``), accumulated."""

    def __call__(self, stage: str):
        return _Stage(self, stage)


class _Stage:
    def __init__(self, owner: dict, stage: str) -> None:
        self.owner, self.stage = owner, stage

    def __enter__(self) -> None:
        self.t = time.perf_counter()

    def __exit__(self, *exc) -> None:
        self.owner[self.stage] = self.owner.get(self.stage, 0.0) + time.perf_counter() - self.t


class FrameWorker:
    """Renders and encodes frames of a :class:`Plan` (one per process)."""

    def __init__(self, plan: Plan, *, nthreads: int = 0, reuse_still: bool = True) -> None:
        self.plan = plan
        scene = build_scene(plan.scene_name, seed=plan.seed, static=plan.static)
        self.renderer = Renderer(scene, nthreads=nthreads, reuse_still=reuse_still)
        self.cams = {s.id: SensorCameras.of(s) for s in plan.rig.sensors}

    def render(self, event: Event) -> EncodedFrame:
        """Render and encode one frame."""
        return self.encode(self.render_raw(event))

    def render_raw(self, event: Event) -> tuple:
        """Render one frame (the part that needs the renderer; the rest is :meth:`encode`)."""
        t_us, order, sid, i = event
        plan = self.plan
        spec = plan.rig.sensor(sid)
        sched = plan.schedules[sid]
        fn = int(sched.frame_number[i])
        # a duplicated frame is rendered exactly as the frame it copies (same instant, same noise)
        src = int(sched.source_frame_number[i]) if sched.source_frame_number is not None else fn
        effects = SensorEffects.of(plan.effects) if sid == plan.rig.target else None
        timings = _StageTimings()
        before = dict(self.renderer.stage_s)
        rng = np.random.default_rng([plan.seed, 3, order, src])
        frame = render_frame(spec, self.cams[sid], self.renderer, t_us * 1e-6, rng=rng, effects=effects,
                             timings=timings)
        for stage, s in self.renderer.stage_s.items():
            timings[stage] = s - before[stage]
        return sid, i, fn, frame, timings

    def encode(self, raw: tuple) -> EncodedFrame:
        """Encode a rendered frame (thread-safe: OpenCV and hashlib release the GIL)."""
        sid, i, fn, frame, timings = raw
        spec = self.plan.rig.sensor(sid)
        with timings("encode"):  # depth_counts: encode_depth's numbers, compiled
            files = {"depth": (_depth_png(depth_counts(frame.depth, spec.depth_unit_m)), "png"),
                     "color": codec.encode_color(frame.color, encoding=self.plan.color_encoding_of(sid),
                                                 params=codec.PNG_FAST),
                     "truth": (_depth_png(depth_counts(frame.truth_depth, TRUTH_DEPTH_UNIT_M)), "png")}
            files = {k: (data, ext, sha256_bytes(data)) for k, (data, ext) in files.items()}
        return EncodedFrame(sid, i, fn, files, dict(timings))


def _depth_png(counts: np.ndarray) -> bytes:
    """Session and truth depth counts as PNG (:data:`depthbench.frames.PNG_FAST`: the pixels of the
    recorder's :data:`~depthbench.frames.PNG_RLE`, a fifth of its CPU)."""
    return codec.encode_png(counts, params=codec.PNG_FAST)


#: Frames rendered ahead of the one being encoded, in one process.
_AHEAD = 2


def render_frames(plan: Plan, events: list[Event], *, workers: int, reference: bool = False) -> Iterator[EncodedFrame]:
    """Yield the encoded frames of ``events`` in order.

    ``workers`` <= 1: in this process; Embree casts on every core, and a thread encodes frame
    n while frame n + 1 renders (the encoders and the numba kernels release the GIL).
    ``workers`` > 1: that many worker processes (:mod:`capture.sim.worker`).
    ``reference``: the straightforward way, the yardstick of ``perf/simulate_fps.py``: one
    process, every pixel cast every frame (no reuse of still geometry), encoding after rendering."""
    if reference:
        worker = FrameWorker(plan, nthreads=0, reuse_still=False)
        yield from (worker.render(ev) for ev in events)
        return
    if workers <= 1:
        yield from _render_in_process(plan, events)
        return
    from capture.sim.worker import WorkerPool

    pool = WorkerPool(plan, workers)
    try:
        yield from pool.map(events)
    except BaseException:
        pool.kill()
        raise
    pool.close()


def _render_in_process(plan: Plan, events: list[Event]) -> Iterator[EncodedFrame]:
    worker = FrameWorker(plan, nthreads=0)
    pending: deque[Future] = deque()
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="sim-encode") as pool:
        try:
            for ev in events:
                pending.append(pool.submit(worker.encode, worker.render_raw(ev)))
                while len(pending) > _AHEAD:
                    yield pending.popleft().result()
            while pending:
                yield pending.popleft().result()
        except BaseException:
            for f in pending:
                f.cancel()
            raise
