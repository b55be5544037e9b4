"""``simulate()``: write a simulated RGB-D session with ground truth.

The library function behind ``depthbench capture simulate``. It plans the run (rig, scene,
clocks, which frames exist), then renders every frame of every sensor in scene-time order,
writing them through :class:`capture.session.SessionWriter` (staged: an error leaves nothing)
and the noise-free depth to ``truth/``.
"""
from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from capture.camera import Intrinsics
from capture.session import SessionWriter
from capture.sim.clocks import draw_clocks, frame_schedule
from capture.sim.effects import parse_effects
from capture.sim.errors import SimulationError
from capture.sim.output import Plan, TruthWriter, session_manifest
from capture.sim.pipeline import EncodedFrame, Event, render_frames
from capture.sim.rigs import Rig, build_rig
from capture.sim.scene import build_scene
from capture.sim.sensors import Timings
from depthbench.fsutil import atomic_write_bytes

COLOR_ENCODINGS = ("auto", "png", "jpeg")


@dataclass(frozen=True)
class SimulationResult:
    """What :func:`simulate` wrote.

    ``frames``/``dropped``: frames written / dropped per sensor; ``time_shift_us``: the true
    Delta between the target (LQ) and reference (HQ) host clocks; ``timings_s``: seconds per
    stage summed over the rendering processes (``raycast`` in Embree, ``shade`` texture and
    colour kernels, ``noise`` depth noise models, ``encode`` PNG/JPEG) and seconds of the main
    process (``write`` files and index rows, ``truth`` tables).
    """

    root: Path
    rig: str
    scene: str
    seed: int
    seconds: float
    frames: dict[str, int]
    dropped: dict[str, int]
    time_shift_us: int
    effects: dict[str, float]
    declared: bool
    elapsed_s: float
    timings_s: dict[str, float]
    reference_fps: float = 30.0

    @property
    def scene_frames_per_s(self) -> float:
        """Frames of scene time (one period of the reference sensor, 1/30 s by default, of every
        stream) simulated per second of wall time."""
        return self.seconds * self.reference_fps / self.elapsed_s if self.elapsed_s > 0 else float("inf")


def simulate(out, *, rig: str = "lq-hq", scene: str = "people", seconds: float = 5.0, seed: int = 0,
             effects=None, undeclared: bool = False, force: bool = False, time_shift_us: int | None = None,
             static: bool = False, scale: float = 1.0, lq_fps: float = 30.0, hq_fps: float = 30.0,
             color_encoding: str = "auto", progress: bool = True, name: str | None = None,
             workers: int | None = None, reference: bool = False,
             frame_phase_us: float | None = None, lq_profile: str | None = None,
             hq_profile: str | None = None) -> SimulationResult:
    """Simulate rig ``rig`` filming scene ``scene`` for ``seconds`` and write a session to ``out``.

    Args:
        out: session folder to create (refused if it exists and not ``force``).
        rig: ``lq-hq``, ``multiview4`` or ``multiview4-hq`` (:mod:`capture.sim.rigs`).
        scene: ``people``, ``balloons`` or ``planes`` (:mod:`capture.sim.scene`).
        seconds: scene time to simulate (s). seed: makes the run deterministic (same bytes).
        effects: ``{"depth_scale": 1.02}`` or ``["depth_scale=1.02"]`` (:mod:`capture.sim.effects`).
        undeclared: write the effects to ``truth/`` only, not to ``session.json``.
        time_shift_us: the true Delta (µs) of the target (LQ) host clock against the reference (HQ);
            drawn uniformly within +-55 ms when None (:func:`capture.sim.clocks.draw_shift_us`: inside align's
            +-60 ms search range with a margin).
        frame_phase_us: how long after each HQ (reference) frame the LQ (target) frame is exposed, in
            scene time, within one LQ period either way (:func:`capture.sim.clocks.draw_clocks`);
            drawn with the seed when None. It sets how far apart in time a pair's two frames fall
            (the time shift does not: it moves the stamps, not the exposures).
        static: freeze the scene (the time shift is then unobservable).
        scale: multiply every image size (e.g. 0.25 for tiny tests). lq_fps, hq_fps: frame rates.
        color_encoding: ``png`` or ``jpeg`` for every colour stream; ``auto``: PNG for LQ, JPEG for HQ.
        lq_profile, hq_profile: measured sensor profile of the LQ / view sensors and of the HQ
            sensor (``D435``, ``D415``, ``Kinect v1``; ``Azure Kinect``); None: default noise
            (:func:`capture.sim.rigs.build_rig`). Written to ``sensors.X.noise.profile``.
        workers: rendering processes (None: 1 on two cores, else one per core, at most 4, for
            runs of 240+ frames; 1: render in this process; the bytes do not depend on it).
        reference: render the straightforward way (one process, every pixel every frame, encoding
            after rendering): the yardstick that ``perf/simulate_fps.py`` compares against.
    Returns:
        :class:`SimulationResult`. Read the truth with :func:`capture.truth.read_truth`.
    """
    started = time.perf_counter()
    plan = make_plan(rig=rig, scene=scene, seconds=seconds, seed=seed, effects=effects, undeclared=undeclared,
                     time_shift_us=time_shift_us, static=static, scale=scale, lq_fps=lq_fps, hq_fps=hq_fps,
                     color_encoding=color_encoding, name=name, frame_phase_us=frame_phase_us, lq_profile=lq_profile,
                     hq_profile=hq_profile)
    try:
        writer = SessionWriter(out, session_manifest(plan), force=force, staged=True)
    except OSError as exc:
        raise SimulationError(f"{out}: cannot create the session folder ({exc.strerror or exc})") from None
    timings = Timings()
    try:
        truth = TruthWriter(writer.root, plan)
        _render_all(plan, writer, truth, timings, progress=progress, workers=workers, reference=reference)
        with timings("truth"):
            truth.close()
        root = writer.close()
    except OSError as exc:
        writer.abort()
        raise SimulationError(f"{out}: writing failed, nothing was kept ({exc.strerror or exc})") from None
    except BaseException:
        writer.abort()
        raise
    return SimulationResult(
        Path(root), plan.rig.name, plan.scene_name, plan.seed, plan.seconds,
        {sid: len(s) for sid, s in plan.schedules.items()},
        {sid: len(s.dropped_frame_numbers) for sid, s in plan.schedules.items()},
        plan.time_shift_us, dict(plan.effects), plan.declared, time.perf_counter() - started, dict(timings),
        plan.rig.sensor(plan.rig.reference).fps)


# ----------------------------------------------------------------------------- planning
def make_plan(*, rig: str, scene: str, seconds: float, seed: int, effects, undeclared: bool,
              time_shift_us: int | None, static: bool, scale: float, lq_fps: float, hq_fps: float,
              color_encoding: str = "auto", name: str | None = None, frame_phase_us: float | None = None,
              lq_profile: str | None = None, hq_profile: str | None = None) -> Plan:
    """Check the options and decide everything but the pixels: rig, clocks, which frames exist."""
    effects = parse_effects(effects)
    _check_options(seconds=seconds, seed=seed, time_shift_us=time_shift_us, color_encoding=color_encoding)
    _check_frame_phase(frame_phase_us, lq_fps)
    built = _apply_lens_effect(build_rig(rig, scale=scale, lq_fps=lq_fps, hq_fps=hq_fps, lq_profile=lq_profile,
                                         hq_profile=hq_profile), effects)
    build_scene(scene, seed=seed)  # validates the name early, before anything is written
    rng = np.random.default_rng([int(seed), 1])
    clocks = draw_clocks({s.id: s.fps for s in built.sensors}, reference=built.reference, target=built.target,
                         rng=rng, time_shift_us=time_shift_us, drift_ppm=effects.get("clock_drift_ppm", 0.0),
                         drop_rate=effects.get("frame_drop_rate", 0.0),
                         duplicate_rate=effects.get("frame_duplicate_rate", 0.0), frame_phase_us=frame_phase_us)
    schedules = {sid: frame_schedule(c, seconds=seconds, rng=np.random.default_rng([int(seed), 2, i]))
                 for i, (sid, c) in enumerate(clocks.items())}
    return Plan(built, scene, int(seed), float(seconds), bool(static), float(scale), effects, not undeclared,
                clocks, schedules, color_encoding, name or f"sim-{rig}-{scene}-seed{seed}")


def _check_options(*, seconds: float, seed: int, time_shift_us, color_encoding: str) -> None:
    if not (isinstance(seconds, (int, float)) and 0 < seconds <= 600):
        raise SimulationError(f"--seconds: {seconds} must be within (0, 600]")
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise SimulationError(f"--seed: {seed} must be a non-negative integer")
    if time_shift_us is not None and abs(int(time_shift_us)) > 600_000:
        raise SimulationError(f"--time-shift-ms: {time_shift_us / 1000:g} ms is beyond +-600 ms")
    if color_encoding not in COLOR_ENCODINGS:
        raise SimulationError(f"--color-format: {color_encoding!r} is not one of {', '.join(COLOR_ENCODINGS)}")


def _check_frame_phase(frame_phase_us, lq_fps) -> None:
    if frame_phase_us is None:
        return
    period_ms = 1000.0 / lq_fps if isinstance(lq_fps, (int, float)) and lq_fps > 0 else float("inf")
    try:
        ms = float(frame_phase_us) / 1000
    except (TypeError, ValueError):
        ms = float("nan")
    if not abs(ms) < period_ms:
        raise SimulationError(f"--frame-phase-ms: {ms:g} ms is not within one LQ frame period (+-{period_ms:.4g} ms)")


def _apply_lens_effect(rig: Rig, effects: dict[str, float]) -> Rig:
    """Render the target camera through radial distortion k1 (depth and co-registered colour), and
    the reference's colour camera through ``hq_distortion_k1``."""
    k1 = effects.get("distortion_k1", 0.0)
    if k1:
        spec = rig.sensor(rig.target)
        K = _with_k1(spec.depth, k1)
        rig = rig.with_sensor(replace(spec, depth=K, color=K if spec.color == spec.depth else _with_k1(spec.color, k1)))
    k1 = effects.get("hq_distortion_k1", 0.0)
    if k1:
        spec = rig.sensor(rig.reference)
        if spec.color_is_depth:
            raise SimulationError(f"--effect hq_distortion_k1: the reference sensor {spec.id!r} has no separate colour "
                                  "camera")
        rig = rig.with_sensor(replace(spec, color=_with_k1(spec.color, k1)))
    return rig


def _with_k1(d: Intrinsics, k1: float) -> Intrinsics:
    return Intrinsics(d.width, d.height, d.fx, d.fy, d.cx, d.cy, "opencv", (k1, 0.0, 0.0, 0.0, 0.0))


# ----------------------------------------------------------------------------- rendering
def _events(plan: Plan) -> list[Event]:
    """(scene time µs, sensor order, sensor, index in its schedule) for every frame, in time order."""
    ev = [(int(t), order, s.id, i) for order, s in enumerate(plan.rig.sensors)
          for i, t in enumerate(plan.schedules[s.id].scene_time_us)]
    return sorted(ev)


def _default_workers(n_events: int) -> int:
    """Rendering processes: on 2 cores one process does best (Embree casts on both cores and a
    thread encodes while the next frame renders); with more cores, one process per core (at
    most 4) for runs long enough (240+ frames) to pay for their start (~2 s CPU each)."""
    cores = os.cpu_count() or 1
    return 1 if cores <= 2 or n_events < 240 else min(cores, 4)


def _render_all(plan: Plan, writer: SessionWriter, truth: TruthWriter, timings: Timings, *, progress: bool,
                workers: int | None, reference: bool = False) -> None:
    events = _events(plan)
    workers = _default_workers(len(events)) if workers is None else workers
    bar = tqdm(total=len(events), desc=f"simulate {plan.rig.name}", unit="frame", file=sys.stderr,
               disable=not progress, leave=False)
    with bar:
        for enc in render_frames(plan, events, workers=workers, reference=reference):
            for stage, s in enc.stage_s.items():
                timings[stage] = timings.get(stage, 0.0) + s
            with timings("write"):
                _write_frame(plan, writer, truth, enc)
            bar.update(1)


def _write_frame(plan: Plan, writer: SessionWriter, truth: TruthWriter, enc: EncodedFrame) -> None:
    sched = plan.schedules[enc.sensor]
    dev, host = int(sched.device_timestamp_us[enc.index]), int(sched.host_timestamp_us[enc.index])
    for stream in ("depth", "color"):
        data, ext, sha = enc.files[stream]
        rel = f"{enc.sensor}/{stream}/{enc.frame_number:08d}.{ext}"
        atomic_write_bytes(writer.root / rel, data)
        writer.index_frame(enc.sensor, stream, enc.frame_number, dev, host, rel, sha)
    data, _, sha = enc.files["truth"]
    truth.add(enc.sensor, enc.index, data, sha)
