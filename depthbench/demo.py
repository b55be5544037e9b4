"""``depthbench demo``: every stage end to end on a small simulated rig.

simulate (lq-hq rig, moving people and balloons, ground truth)
  -> align (time shift search + extrinsic fit + HQ depth warped onto the LQ image)
  -> a small training corpus (other seeds, people and balloons) simulated and aligned the same way,
     and SSDD's two levels trained on it with the ``tiny`` config (``learned``)
  -> bench (every registered method, the trained SSDD models included, scored against the warped HQ
     reference and the truth)
  -> leaderboard (Markdown + HTML + figures)

Each step calls the stage's library function (:func:`capture.sim.simulate`,
:func:`align.pipeline.align_session`, :func:`bench.runner.run_benchmark`) with the values the
equivalent command line would use, and prints that command so a user can repeat the step by hand.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from depthbench.errors import DepthbenchError
from depthbench.fsutil import check_output_free


@dataclass
class DemoStep:
    """One stage of the demo: what it does, the equivalent command, the library call, its output."""

    name: str
    command: str
    call: Callable[[], Any]
    output: Path
    seconds: float = 0.0
    status: str = "pending"


@dataclass
class DemoResult:
    out: Path
    steps: list[DemoStep] = field(default_factory=list)

    @property
    def leaderboard(self) -> Path:
        return self.out / "results" / "leaderboard.md"


@dataclass(frozen=True)
class DemoConfig:
    """The demo's knobs: scene ``seconds``, ``seed``, the sensors' ``time_shift_ms`` (None: drawn from the
    seed), image ``scale`` (1 = the sensors' own size; the default 0.5 = 320x240 LQ frames keeps the
    whole demo, training included, within minutes on two cores), the benchmark's ``methods`` and local
    ``jobs``; ``probes`` and ``reports`` shrink a test run."""

    seconds: float = 3.0
    seed: int = 0
    time_shift_ms: float | None = None
    scale: float = 0.5
    methods: str = "all"
    jobs: int | None = None
    progress: bool = True
    probes: int | None = None      # HQ frames that fit the time shift and extrinsics (None: align's default)
    reports: bool = True           # the alignment report and the leaderboard's Markdown/HTML/figures
    learned: bool = True           # train SSDD (tiny) on a corpus of other seeds and score it too
    corpus_seconds: float = 2.0    # scene time per training sequence (three sequences: two train, one validation)


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
    align_opts = {"report": config.reports, **({} if config.probes is None else {"probes": config.probes})}
    steps = [
        DemoStep(name="simulate an LQ+HQ rig", output=session,
                 command=_command("capture simulate --rig lq-hq --scene people --seconds", f"{config.seconds:g}",
                                  "--seed", config.seed, scale, "--out", session, shift, f),
                 call=lambda: simulate(session, rig="lq-hq", scene="people", seconds=config.seconds,
                                       seed=config.seed, force=force, time_shift_us=shift_us, scale=config.scale,
                                       progress=config.progress)),
        DemoStep(name="align HQ onto LQ", output=aligned,
                 command=_command("align", session, "--out", aligned, probes, no_report, f),
                 call=lambda: align_session(session, aligned, force=force, progress=config.progress, **align_opts)),
    ]
    params, weights_args = {}, ""
    if config.learned:
        learned_steps, params = _learned_steps(out, config, force=force)
        steps += learned_steps
        if config.methods != "all":
            params = {k: v for k, v in params.items() if k in config.methods.split(",")}
        weights_args = " ".join(f"--param {m}.weights={p['weights']}" for m, p in params.items())
    steps.append(DemoStep(
        name="benchmark every method", output=results,
        command=_command("bench run --data", aligned, "--methods", config.methods, weights_args, "--out", results,
                         jobs, no_report, f),
        call=lambda: run_benchmark([aligned], config.methods, results, force=force, jobs=config.jobs,
                                   progress=None if config.progress else False, report=config.reports, params=params)))
    return steps


def _learned_steps(out: Path, config: DemoConfig, *, force: bool) -> tuple[list[DemoStep], dict]:
    """Corpus (three sequences of other seeds than the benchmark session) and SSDD trained with ``tiny``."""
    from bench.corpus import CorpusSpec, make_corpus
    from bench.executors import ExecutorSpec
    from methods.nn.train import train_method

    corpus, run = out / "corpus", out / "ssdd"
    seeds = tuple(1000 + 10 * config.seed + k for k in (1, 2, 3))
    spec = CorpusSpec(seeds=seeds, seconds=config.corpus_seconds, scale=config.scale, validation=1, test=0,
                      probes=config.probes, name=f"demo-corpus-seed{config.seed}")
    ex = ExecutorSpec(jobs=config.jobs or 2)
    f = "--force" if force else ""
    steps = [
        DemoStep(name="simulate + align a training corpus", output=corpus,
                 command=_command("bench corpus --out", corpus, "--seeds", ",".join(map(str, seeds)), "--seconds",
                          f"{config.corpus_seconds:g}", "--scale", f"{config.scale:g}", "--validation 1",
                          f"--jobs {ex.jobs}", f),
                 call=lambda: make_corpus(corpus, spec, executor=ex, force=force,
                                          progress=None if config.progress else False)),
        DemoStep(name="train SSDD (both levels, tiny)", output=run,
                 command=_command("methods train ssdd_lstm --dataset", corpus / "training.json", "--config tiny --out", run, f),
                 call=lambda: train_method("ssdd_lstm", dataset=corpus / "training.json", config="tiny", out=run,
                                           force=force, progress=config.progress)),
    ]
    params = {m: {"weights": str(run / f"{m}.safetensors")} for m in ("ssdd_unet", "ssdd_lstm")}
    return steps, params


def run_demo(out: str | Path, *, seconds: float = 3.0, seed: int = 0, force: bool = False,
             time_shift_ms: float | None = None, config: DemoConfig | None = None) -> DemoResult:
    """Run the stages in order into ``out`` (``session/``, ``aligned/``, ``results/``).

    ``config`` (None: built from ``seconds``, ``seed`` and ``time_shift_ms``) sets every knob.
    Raises the first stage's error (a :class:`DepthbenchError`, one line).
    """
    config = config or DemoConfig(seconds=seconds, seed=seed, time_shift_ms=time_shift_ms)
    if not config.seconds > 0:
        raise DepthbenchError(f"demo: seconds must be positive, got {config.seconds}")
    out = Path(out)
    check_output_free(out, force=force, what="demo output folder")
    out.mkdir(parents=True, exist_ok=True)
    result = DemoResult(out)
    for step in plan(out, config, force=force):
        result.steps.append(step)
        print(f"[demo] {step.name}: {step.command}", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        try:
            step.call()
        except DepthbenchError:
            step.status = "failed"
            raise
        finally:
            step.seconds = time.perf_counter() - t0
        step.status = "done"
    return result


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "demo", help="run every stage end to end on a small simulated rig",
        description="Simulate a RealSense-like LQ sensor beside a Kinect-like HQ sensor, align them, run every "
                    "registered denoising method and write the leaderboard. Takes a few minutes on two cores.")
    p.add_argument("--out", required=True, help="output folder (session/, aligned/, results/ inside)")
    p.add_argument("--seconds", type=float, default=3.0, help="seconds of scene time to simulate (default 3)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the simulated scene and clocks (default 0)")
    p.add_argument("--time-shift-ms", type=float, default=25.0,
                   help="clock shift between the sensors (default 25 ms; seed 0 would draw 59 ms, on the edge of "
                        "the alignment's +-60 ms search, which alignment refuses)")
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
    print(f"\ndemo finished in {sum(s.seconds for s in result.steps):.0f} s; outputs:")
    for step in result.steps:
        print(f"  {step.name:<34} {step.status:<6} {step.seconds:>6.0f} s  {step.output}")
    if result.leaderboard.exists():
        print(f"\nleaderboard: {result.leaderboard}  (HTML: {result.leaderboard.with_suffix('.html')})")
    return 0
