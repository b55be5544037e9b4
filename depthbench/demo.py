"""``depthbench demo``: every stage end to end on a small simulated rig.

simulate (lq-hq rig, moving people and balloons, ground truth)
  -> align (time shift search + extrinsic fit + HQ depth warped onto the LQ image)
  -> bench (every registered method scored against the warped HQ reference and the truth)
  -> leaderboard (Markdown + HTML + figures)

Each step runs through the same command line a user types, so the demo also proves the
commands. A stage whose package is not installed is reported and skipped.
"""
from __future__ import annotations

import importlib.util
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from depthbench.errors import DepthbenchError
from depthbench.fsutil import check_output_free


@dataclass
class DemoStep:
    name: str
    module: str
    argv: list[str]
    output: Path
    seconds: float = 0.0
    status: str = "pending"


@dataclass
class DemoResult:
    out: Path
    steps: list[DemoStep] = field(default_factory=list)


def plan(out: Path, *, seconds: float, seed: int, force: bool, time_shift_ms: float | None) -> list[DemoStep]:
    session, aligned, results = out / "session", out / "aligned", out / "results"
    f = ["--force"] if force else []
    sim = ["capture", "simulate", "--rig", "lq-hq", "--scene", "people", "--seconds", f"{seconds:g}",
           "--seed", str(seed), "--out", str(session), *f]
    if time_shift_ms is not None:
        sim += ["--time-shift-ms", f"{time_shift_ms:g}"]
    return [
        DemoStep("simulate an LQ+HQ rig", "capture.commands.simulate", sim, session),
        DemoStep("align HQ onto LQ", "align.cli", ["align", str(session), "--out", str(aligned), *f], aligned),
        DemoStep("benchmark every method", "bench.cli",
                 ["bench", "run", "--data", str(aligned), "--methods", "all", "--out", str(results), *f], results),
    ]


def run_demo(out: str | Path, *, seconds: float = 3.0, seed: int = 0, force: bool = False,
             time_shift_ms: float | None = None) -> DemoResult:
    """Run the stages in order; raises the first stage's error (a :class:`DepthbenchError`)."""
    from depthbench.cli import main

    out = Path(out)
    check_output_free(out, force=force, what="demo output folder")
    out.mkdir(parents=True, exist_ok=True)
    result = DemoResult(out)
    for step in plan(out, seconds=seconds, seed=seed, force=force, time_shift_ms=time_shift_ms):
        result.steps.append(step)
        if importlib.util.find_spec(step.module) is None:
            step.status = "skipped (stage not installed)"
            continue
        print(f"[demo] {step.name}: depthbench {' '.join(step.argv)}", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        code = main(step.argv)
        step.seconds = time.perf_counter() - t0
        if code != 0:
            step.status = f"failed (exit {code})"
            raise DepthbenchError(f"demo step '{step.name}' failed with exit status {code}")
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
    p.add_argument("--time-shift-ms", type=float, default=None,
                   help="clock shift between the sensors; default: drawn within +-60 ms from the seed")
    p.add_argument("--force", action="store_true", help="replace an existing output folder")
    p.set_defaults(func=_cli)


def _cli(args) -> int:
    if args.seconds <= 0:
        raise DepthbenchError(f"--seconds must be positive, got {args.seconds}")
    result = run_demo(args.out, seconds=args.seconds, seed=args.seed, force=args.force,
                      time_shift_ms=args.time_shift_ms)
    print(f"\ndemo finished in {sum(s.seconds for s in result.steps):.0f} s; outputs:")
    for step in result.steps:
        print(f"  {step.name:<26} {step.status:<32} {step.output}")
    report = result.out / "results" / "leaderboard.md"
    if report.exists():
        print(f"\nleaderboard: {report}  (HTML: {report.with_suffix('.html')})")
    return 0
