"""``depthbench demo``: every stage end to end on a small simulated rig.

simulate (lq-hq rig, moving people and balloons, ground truth)
  -> align (time shift search + extrinsic fit + HQ depth warped onto the LQ image)
  -> ``learned``: a small training corpus (other seeds, people and balloons) simulated and aligned the
     same way, and a one-second four-view session (``multiview4``) aligned by the suite's multi-view
     alignment; SSDD's two levels and DDRNet (denoise, and denoise + refine) trained on the corpus,
     DDD self-supervised on the four views, all with the ``tiny`` config
  -> bench (every registered method, the trained models included, scored against the warped HQ
     reference and the truth): the seed's Table I with all its columns
  -> leaderboard (Markdown + HTML + figures)

Each step calls the stage's library function (:func:`capture.sim.simulate`,
:func:`align.pipeline.align_session`, :func:`bench.corpus.make_corpus`, :func:`methods.nn.train.train_method`,
:func:`bench.runner.run_benchmark`) with the values the equivalent command line would use, and prints
that command so a user can repeat the step by hand. Steps that do not depend on each other run at
the same time in ``jobs`` worker processes (default 2, the two cores the demo is sized for), each
single-threaded; ``jobs=1`` runs them in order in this process.
"""
from __future__ import annotations

import os
import sys
import time
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, Callable

from depthbench.errors import DepthbenchError
from depthbench.fsutil import check_output_free


@dataclass
class DemoStep:
    """One stage of the demo: what it does, the equivalent command, the library call, its output,
    and the names of the steps it needs first (``call`` is picklable: it may run in a worker process)."""

    name: str
    command: str
    call: Callable[[], Any]
    output: Path
    needs: tuple[str, ...] = ()
    seconds: float = 0.0        # wall time
    cpu_seconds: float = 0.0    # CPU time of the process that ran it (children not counted)
    status: str = "pending"


@dataclass
class DemoResult:
    out: Path
    steps: list[DemoStep] = field(default_factory=list)
    seconds: float = 0.0   # wall time of the whole demo (steps overlap)

    @property
    def leaderboard(self) -> Path:
        return self.out / "results" / "leaderboard.md"


@dataclass(frozen=True)
class DemoConfig:
    """The demo's knobs: scene ``seconds``, ``seed``, the sensors' ``time_shift_ms`` (None: drawn from the
    seed), image ``scale`` (1 = the sensors' own size; the default 0.5 = 320x240 LQ frames keeps the
    whole demo, training included, within minutes on two cores), the benchmark's ``methods`` and local
    ``jobs`` (also the demo's worker processes; None: 2); ``probes`` and ``reports`` shrink a test run."""

    seconds: float = 2.0
    seed: int = 0
    time_shift_ms: float | None = None
    scale: float = 0.5
    methods: str = "all"
    jobs: int | None = None
    progress: bool = True
    probes: int | None = None      # HQ frames that fit the time shift and extrinsics (None: align's default)
    reports: bool = True           # the alignment report and the leaderboard's Markdown/HTML/figures
    learned: bool = True           # train SSDD, DDRNet and DDD (tiny) and score them too
    corpus_sequences: int = 5      # training corpus: sequences (the last one validation), scenes alternating
    corpus_seconds: float = 1.2    # scene time per training sequence
    multiview_seconds: float = 1.0  # scene time of DDD's four-view session (30 simultaneous samples at 30 fps)
    plane_fit_radius_mm: float | None = None  # None: DDD's 5 mm at 640x480 scaled to the image (5 / scale)

    @property
    def radius_mm(self) -> float:
        """The plane fit's radius: DDD's 5 mm ball holds a pixel neighbourhood at 640x480; at ``scale``
        a pixel spans ``1 / scale`` times as much, so the same neighbourhood needs ``5 / scale`` mm (at
        5 mm and scale 0.5 the plane is undefined beyond ~1.4 m, nearly every frame of the demo)."""
        return self.plane_fit_radius_mm if self.plane_fit_radius_mm is not None else 5.0 / self.scale

    @property
    def workers(self) -> int:
        return self.jobs or 2


def _command(*parts: Any) -> str:
    return "depthbench " + " ".join(str(p) for p in parts if p is not None and p != "")


def plan(out: Path, config: DemoConfig, *, force: bool) -> list[DemoStep]:
    """The demo's steps, in order (nothing runs until each step's ``call``)."""
    from align.pipeline import align_session
    from bench.runner import run_benchmark
    from capture.sim import simulate

    session, aligned, results = out / "session", out / "aligned", out / "results"
    shift_us = None if config.time_shift_ms is None else round(config.time_shift_ms * 1000)
    f = "--force" if force else ""
    shift = "" if config.time_shift_ms is None else f"--time-shift-ms {config.time_shift_ms:g}"
    scale = "" if config.scale == 1.0 else f"--scale {config.scale:g}"
    jobs = "" if config.jobs is None else f"--jobs {config.jobs}"
    probes = "" if config.probes is None else f"--probes {config.probes}"
    no_report = "" if config.reports else "--no-report"
    progress = config.progress and config.workers == 1   # bars of parallel workers would interleave
    align_opts = {"report": config.reports, **({} if config.probes is None else {"probes": config.probes})}
    steps = [
        DemoStep(name="simulate an LQ+HQ rig", output=session,
                 command=_command("capture simulate --rig lq-hq --scene people --seconds", f"{config.seconds:g}",
                                  "--seed", config.seed, scale, "--out", session, shift, f),
                 call=partial(simulate, session, rig="lq-hq", scene="people", seconds=config.seconds,
                              seed=config.seed, force=force, time_shift_us=shift_us, scale=config.scale,
                              progress=progress)),
        DemoStep(name="align HQ onto LQ", output=aligned, needs=("simulate an LQ+HQ rig",),
                 command=_command("align", session, "--out", aligned, probes, no_report, f),
                 call=partial(align_session, session, aligned, force=force, progress=progress, **align_opts)),
    ]
    trained: dict[str, dict] = {}
    if config.learned:
        # the corpora first (the longest chains start at once), then the trainings before the benchmark
        # session: DDD starts as soon as its four views are aligned and SSDD follows it on that worker,
        # while the other runs the corpus, DDRNet, the session and the chained benchmarks (measured:
        # 508 s with the session before the trainings, its worker idle for the last ~120 s)
        corpora, trainings, trained = _learned_steps(out, config, force=force, progress=progress)
        steps = corpora + trainings + steps
    return steps + _bench_steps(aligned, results, config, trained, force=force)


def _weights_args(params: dict) -> str:
    return " ".join(f"--param {m}.weights={p['weights']}" for m, p in params.items())


def _bench_steps(aligned: Path, results: Path, config: DemoConfig, trained: dict[str, dict], *,
                 force: bool) -> list[DemoStep]:
    """The benchmark. Without trainings, or for a chosen list of methods: one run. With every method
    and the trainings: one run per group into the same results folder, each as soon as its methods
    are trained (the filters once the session is aligned), chained so that two runs never write the
    folder at once; each continues the folder (:mod:`bench.runner`: rows already computed are reused)
    and the last, after the last training in ``trained``, scores it and writes the leaderboard."""
    from methods.registry import available

    wanted = None if config.methods == "all" else set(config.methods.split(","))
    params = {m: p for ps in trained.values() for m, p in ps.items() if wanted is None or m in wanted}
    steps: list[DemoStep] = []
    if wanted is None and trained:
        filters = ",".join(n for n, cls in available().items() if not cls.needs_weights())
        groups = [("the filters", filters, {}, "align HQ onto LQ")]
        groups += [(", ".join(ps), ",".join(ps), ps, step) for step, ps in list(trained.items())[:-1]]
        for label, names, ps, after in groups:
            steps.append(_bench_step(f"benchmark {label}", aligned, results, names, ps, radius_mm=config.radius_mm,
                                     needs=(after,) + tuple(s.name for s in steps[-1:]), force=force and not steps))
    needs = ("align HQ onto LQ",) + tuple(trained) + tuple(s.name for s in steps[-1:])
    steps.append(_bench_step("benchmark every method", aligned, results, config.methods, params, needs=needs,
                             radius_mm=config.radius_mm,
                             force=force and not steps, jobs=config.jobs, report=config.reports,
                             progress=None if config.progress else False))
    return steps


def _bench_step(name: str, aligned: Path, results: Path, methods: str, params: dict, *, needs: tuple, force: bool,
                radius_mm: float, jobs: int | None = 1, report: bool = False,
                progress: bool | None = False) -> DemoStep:
    """One ``bench run`` of ``methods`` into ``results``, as a step and as the command it stands for."""
    from bench.metrics import MetricConfig
    from bench.runner import run_benchmark

    return DemoStep(
        name=name, output=results, needs=needs,
        command=_command("bench run --data", aligned, "--methods", methods, _weights_args(params), "--out", results,
                         f"--radius-mm {radius_mm:g}", "" if jobs is None else f"--jobs {jobs}",
                         "" if report else "--no-report", "--force" if force else ""),
        call=partial(run_benchmark, [aligned], methods, results, config=MetricConfig(radius_m=radius_mm / 1000.0),
                     force=force, jobs=jobs, progress=progress, report=report, params=params))


def _learned_steps(out: Path, config: DemoConfig, *, force: bool,
                   progress: bool) -> tuple[list[DemoStep], list[DemoStep], dict[str, dict]]:
    """Two corpora (other seeds than the benchmark session), the tiny trainings on them, and per
    training step the benchmark's ``params`` naming its trained weights (SSDD's step last)."""
    from bench.corpus import CorpusSpec, make_corpus
    from bench.executors import ExecutorSpec
    from methods.nn.train import train_method

    corpus, multiview = out / "corpus", out / "corpus_multiview"
    seeds = tuple(1000 + 10 * config.seed + k for k in range(1, config.corpus_sequences + 1))
    mv_seed = 2000 + 10 * config.seed + 1
    common = dict(scale=config.scale, probes=config.probes, reports=False)   # the session's report is the demo's
    spec = CorpusSpec(seeds=seeds, seconds=config.corpus_seconds, validation=1, test=0,
                      name=f"demo-corpus-seed{config.seed}", **common)
    mv_spec = CorpusSpec(seeds=(mv_seed,), scenes=("people",), seconds=config.multiview_seconds, validation=0,
                         test=0, rig="multiview4", name=f"demo-multiview-seed{config.seed}",
                         **{**common, "probes": config.probes or 8})
    # inside a demo worker the corpus runs its sequences in that worker; alone, in config.jobs processes
    ex = ExecutorSpec(jobs=1 if config.workers > 1 else (config.jobs or 2))
    f = "--force" if force else ""
    probes = "" if config.probes is None else f"--probes {config.probes}"
    corpus_cmd = partial(_command, "bench corpus --scale", f"{config.scale:g}", f"--jobs {ex.jobs} --no-report")
    corpora = [
        DemoStep(name="simulate + align a training corpus", output=corpus,
                 command=corpus_cmd("--out", corpus, "--seeds", ",".join(map(str, seeds)), "--seconds",
                                    f"{config.corpus_seconds:g}", "--validation 1", probes, f),
                 call=partial(make_corpus, corpus, spec, executor=ex, force=force, progress=progress)),
        DemoStep(name="simulate + align four views (DDD)", output=multiview,
                 command=corpus_cmd("--out", multiview, "--rig multiview4 --scenes people --seeds", mv_seed,
                                    "--seconds", f"{config.multiview_seconds:g}", "--validation 0 --probes",
                                    mv_spec.probes, f),
                 call=partial(make_corpus, multiview, mv_spec, executor=ex, force=force, progress=progress)),
    ]
    params, trainings = {}, []
    # started in this order (the scheduler takes ready steps in plan order): DDRNet, whose benchmark chain
    # follows it, before SSDD; DDD's corpus is ready first, so it fills the other worker meanwhile
    for method, label, data, trained in (("ddrnet", "DDRNet (denoise, refine)", corpus, ("ddrnet", "ddrnet_refine")),
                                         ("ssdd_lstm", "SSDD (both levels)", corpus, ("ssdd_unet", "ssdd_lstm")),
                                         ("ddd", "DDD (self-supervised)", multiview, ("ddd",))):
        run = out / "runs" / method.split("_")[0]
        trainings.append(DemoStep(
            name=f"train {label}, tiny", output=run, needs=(corpora[0 if data == corpus else 1].name,),
            command=_command("methods train", method, "--dataset", data / "training.json", "--config tiny --out", run, f),
            call=partial(train_method, method, dataset=data / "training.json", config="tiny", out=run, force=force,
                         progress=progress)))
        params[trainings[-1].name] = {m: {"weights": str(run / f"{m}.safetensors")} for m in trained}
    # the benchmark scores each training's methods when it ends; SSDD, on the critical path, last (see _bench_steps)
    last = trainings[1].name
    return corpora, trainings, {**{k: v for k, v in params.items() if k != last}, last: params[last]}


def _worker_init() -> None:
    """A demo worker: one thread for torch, OpenMP and numba (two workers share two cores); set before
    any of them is imported in the fresh (spawned) process, which is when they read it."""
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ[var] = "1"
    if "torch" in sys.modules:   # imported already (by the main module's re-import): set it directly
        sys.modules["torch"].set_num_threads(1)


def _cpu_timed(call: Callable[[], Any]) -> float:
    """Run ``call``; its CPU seconds in this process (what the step costs on a quiet machine)."""
    t0 = time.process_time()
    call()
    return time.process_time() - t0


def _say(step: DemoStep, what: str) -> None:
    extra = f" ({step.seconds:.0f} s, CPU {step.cpu_seconds:.0f} s)" if what == "done" else f": {step.command}"
    print(f"[demo] {what} {step.name}{extra}", file=sys.stderr, flush=True)


def _run_in_order(steps: list[DemoStep]) -> None:
    for step in steps:
        _say(step, "start")
        t0 = time.perf_counter()
        try:
            step.cpu_seconds = _cpu_timed(step.call)
        except DepthbenchError:
            step.status = "failed"
            raise
        finally:
            step.seconds = time.perf_counter() - t0
        step.status = "done"
        _say(step, "done")


def _run_parallel(steps: list[DemoStep], workers: int) -> None:
    """Every step as soon as the steps it needs are done, at most ``workers`` at once (plan order first)."""
    import multiprocessing

    pending, running = list(steps), {}   # running: Future -> (step, start time)
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"), initializer=_worker_init) as pool:
        while pending or running:
            done = {s.name for s in steps if s.status == "done"}
            for step in [s for s in pending if set(s.needs) <= done][:workers - len(running)]:
                pending.remove(step)
                step.status = "running"
                _say(step, "start")
                running[pool.submit(_cpu_timed, step.call)] = (step, time.perf_counter())
            finished, _ = wait(list(running), return_when=FIRST_COMPLETED)
            for fut in finished:
                step, t0 = running.pop(fut)
                step.seconds = time.perf_counter() - t0
                _finish(step, fut, pool)


def _finish(step: DemoStep, fut: Future, pool: ProcessPoolExecutor) -> None:
    try:
        step.cpu_seconds = fut.result()
    except BaseException:
        step.status = "failed"
        pool.shutdown(cancel_futures=True)
        raise
    step.status = "done"
    _say(step, "done")


def run_demo(out: str | Path, *, seconds: float = DemoConfig.seconds, seed: int = 0, force: bool = False,
             time_shift_ms: float | None = None, config: DemoConfig | None = None) -> DemoResult:
    """Run the stages into ``out`` (``session/``, ``aligned/``, ``results/``; with ``learned``, also
    ``corpus/``, ``corpus_multiview/`` and ``runs/``), independent ones side by side.

    ``config`` (None: built from ``seconds``, ``seed`` and ``time_shift_ms``) sets every knob.
    Raises the first stage's error (a :class:`DepthbenchError`, one line).
    """
    config = config or DemoConfig(seconds=seconds, seed=seed, time_shift_ms=time_shift_ms)
    if not config.seconds > 0:
        raise DepthbenchError(f"demo: seconds must be positive, got {config.seconds}")
    out = Path(out)
    check_output_free(out, force=force, what="demo output folder")
    out.mkdir(parents=True, exist_ok=True)
    result, t0 = DemoResult(out), time.perf_counter()
    steps = plan(out, config, force=force)
    result.steps = steps
    *work, bench = steps
    if config.workers > 1 and len(work) > 1:
        _run_parallel(work, config.workers)
    else:
        _run_in_order(work)
    _run_in_order([bench])
    result.seconds = time.perf_counter() - t0
    return result


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "demo", help="run every stage end to end on a small simulated rig",
        description="Simulate a RealSense-like LQ sensor beside a Kinect-like HQ sensor, align them, run every "
                    "registered denoising method and write the leaderboard. Takes a few minutes on two cores.")
    p.add_argument("--out", required=True, help="output folder (session/, aligned/, results/ inside)")
    p.add_argument("--seconds", type=float, default=DemoConfig.seconds,
                   help=f"seconds of scene time to simulate (default {DemoConfig.seconds:g})")
    p.add_argument("--seed", type=int, default=0, help="random seed of the simulated scene and clocks (default 0)")
    p.add_argument("--time-shift-ms", type=float, default=25.0,
                   help="clock shift between the sensors (default 25 ms, not the simulator's own draw for the seed, "
                        "so that the demo's benchmark session stays the one its numbers were measured on)")
    p.add_argument("--scale", type=float, default=DemoConfig.scale,
                   help=f"image scale of the simulated sensors (default {DemoConfig.scale:g}: 320x240 LQ; 1 = 640x480)")
    p.add_argument("--force", action="store_true", help="replace an existing output folder")
    p.set_defaults(func=_cli)


def _cli(args) -> int:
    if args.seconds <= 0:
        raise DepthbenchError(f"--seconds must be positive, got {args.seconds}")
    if not 0 < args.scale <= 1:
        raise DepthbenchError(f"--scale must be in (0, 1], got {args.scale}")
    result = run_demo(args.out, force=args.force,
                      config=DemoConfig(seconds=args.seconds, seed=args.seed, time_shift_ms=args.time_shift_ms,
                                        scale=args.scale))
    print(f"\ndemo finished in {result.seconds:.0f} s (steps overlap: two at a time); outputs:")
    for step in result.steps:
        print(f"  {step.name:<40} {step.status:<6} {step.seconds:>6.0f} s (CPU {step.cpu_seconds:>4.0f} s)  {step.output}")
    if result.leaderboard.exists():
        print(f"\nleaderboard: {result.leaderboard}  (HTML: {result.leaderboard.with_suffix('.html')})")
    return 0
