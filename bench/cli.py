"""``depthbench bench ...``: run the benchmark, rebuild the leaderboard, import external aligned data.

A thin parser over :func:`bench.runner.run_benchmark`, :func:`bench.report.write_report` and
:func:`align.external.import_ddrnet`.
"""
from __future__ import annotations

import argparse

from bench.errors import BenchError

_RUN_EPILOG = """\
The results folder (--out):
  new or empty           built aside and published when the run is complete (a failed run leaves nothing)
  a results folder       continued: cached (method version, dataset checksum, frame) results are reused,
                         new ones added; the table keeps earlier runs' methods/datasets that this run does
                         not name, and replaces those it recomputes (a changed method version or dataset)
  anything else          refused unless --force (which replaces it and drops its cache)

examples:
  depthbench bench run --data aligned/ --methods all --out results/
  depthbench bench run --data A1 --data A2 --methods raw,bf,rgf --out results/ --workers 2
  depthbench bench import-ddrnet ../shared/data/real/ddrnet_person --out ddrnet_aligned/
"""


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {v}")
    return v


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not v > 0 or v != v or v == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return v


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "bench", help="score methods against the reference and write the leaderboard",
        description="Score denoising methods on aligned datasets (MSE/RMSE/MAE, DDD's plane-fit RMSE, fill rate), "
                    "locally or on a Dask cluster, and write the leaderboard (Markdown + self-contained HTML).")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=type(parser))
    sub.required = True

    p = sub.add_parser("run", help="run methods x datasets x frames into a results folder",
                       description="Run every method on every frame of every dataset, score it against the HQ "
                                   "reference (and the truth of simulated data), cache each result and write "
                                   "RESULTS/results.parquet and the leaderboard.",
                       epilog=_RUN_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", action="append", required=True, metavar="ALIGNED",
                   help="aligned dataset folder, or a folder of them (repeatable)")
    p.add_argument("--methods", default="all",
                   help="'all' (every registered method) or a comma-separated list, e.g. raw,bf,jbf,rgf "
                        "(bf/jbf/rgf name bilateral/joint_bilateral/rolling_guidance); default: all")
    p.add_argument("--out", required=True, metavar="RESULTS", help="results folder (see below)")
    p.add_argument("--allow-train-frames", action="store_true",
                   help="score learned methods even on datasets of their own training/validation split "
                        "(refused by default; such columns are marked in the key and the leaderboard)")
    p.add_argument("--param", action="append", default=[], metavar="METHOD.K=V",
                   help="a parameter of one method, e.g. bf.sigma_color=0.02 or ssdd_unet.weights=RUN/model.safetensors "
                        "(repeatable; a learned method joins 'all' once its weights are given)")
    ex = p.add_mutually_exclusive_group()
    ex.add_argument("--jobs", type=_positive_int, metavar="N",
                    help="local worker processes (default: the number of CPUs; 1 = in this process)")
    ex.add_argument("--workers", type=_positive_int, metavar="N",
                    help="run on a local Dask cluster with N worker processes")
    ex.add_argument("--scheduler", metavar="ADDRESS",
                    help="run on the Dask cluster whose scheduler listens at ADDRESS (tcp://host:8786); "
                         "datasets must be readable at the same paths on its workers")
    p.add_argument("--radius-mm", type=_positive_float, default=5.0, metavar="MM",
                   help="plane-fit neighbourhood radius in mm (DDD: 5; default 5)")
    p.add_argument("--no-report", action="store_true", help="write the table only, not the leaderboard")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar on stderr (default: when stderr is a terminal)")
    p.add_argument("--force", action="store_true",
                   help="replace an --out that cannot be continued (another schema version or metric parameters, "
                        "or not a results folder); drops its cache")
    p.set_defaults(func=_run)

    _add_corpus(sub)

    p = sub.add_parser("report", help="rebuild the leaderboard from a results folder's table",
                       description="Rebuild RESULTS/leaderboard.md, leaderboard.html and figures/ from "
                                   "RESULTS/results.parquet (and the depth previews for the qualitative figure). "
                                   "Nothing is recomputed.")
    p.add_argument("results", metavar="RESULTS", help="results folder written by 'depthbench bench run'")
    p.add_argument("--bootstrap", type=_positive_int, default=2000, metavar="N",
                   help="bootstrap resamples for the 95 %% intervals (default 2000)")
    p.add_argument("--seed", type=int, default=0, help="bootstrap random seed (default 0)")
    p.set_defaults(func=_report)

    p = sub.add_parser("import-ddrnet", help="import DDRNet's raw/fused depth pairs as aligned datasets",
                       description="Import the DDRNet sample layout (per group: depth_map/, high_quality_depth/, "
                                   "mask/, optional color_map/; uint16 PNG in mm, 640x480) as aligned datasets: raw "
                                   "depth as LQ, the fused depth as reference, the mask as ROI, the authors' "
                                   "intrinsics (fx 536.628, fy 536.606, cx 310.591, cy 234.759).")
    p.add_argument("src", metavar="SRC", help="a group folder, or a folder of groups (one dataset per group)")
    p.add_argument("--out", required=True, metavar="ALIGNED", help="output: the dataset, or a folder of datasets")
    p.add_argument("--force", action="store_true", help="replace an existing output")
    p.set_defaults(func=_import_ddrnet)

    from bench.diagnose.cli import add_parser as add_diagnose  # issue 13: sensor error model

    add_diagnose(sub)


def parse_seeds(text: str) -> tuple[int, ...]:
    """``101-105`` or ``101,103,110`` -> seeds."""
    out: list[int] = []
    try:
        for part in text.split(","):
            a, dash, b = part.strip().partition("-")
            out += list(range(int(a), int(b) + 1)) if dash else [int(a)]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seeds like 101-105 or 1,4,9, got {text!r}") from None
    return tuple(out)


def _add_corpus(sub) -> None:
    p = sub.add_parser(
        "corpus", help="simulate and align a training corpus for the learned methods (with a training manifest)",
        description="Simulate one LQ+HQ session per seed (scenes and time shifts cycled), align each exactly as "
                    "'depthbench align' does, and write CORPUS/training.json naming every aligned dataset, its "
                    "checksum and its split (train/validation/test by sequence). Runs on the benchmark's "
                    "executors (--jobs, --workers, --scheduler).",
        epilog="Example: depthbench bench corpus --out corpus --seeds 101-106 --scenes people,balloons "
               "--validation 1 --test 1, then: depthbench methods train ssdd_lstm --dataset corpus/training.json "
               "--config tiny --out runs/ssdd")
    p.add_argument("--out", required=True, metavar="CORPUS", help="corpus folder to create")
    p.add_argument("--seeds", type=parse_seeds, default=(101, 102, 103, 104, 105), help="simulator seeds, one sequence "
                   "each (default 101-105); use other seeds than your benchmark sessions")
    p.add_argument("--scenes", default="people,balloons", help="scenes cycled over the seeds (default people,balloons)")
    p.add_argument("--seconds", type=_positive_float, default=3.0, help="seconds per sequence (default 3)")
    p.add_argument("--scale", type=_positive_float, default=0.5, help="image size factor (default 0.5: 320x240)")
    p.add_argument("--time-shifts-ms", default="", metavar="MS,MS,...",
                   help="LQ-vs-HQ clock shifts cycled over the seeds (default: drawn within +-55 ms per seed)")
    p.add_argument("--validation", type=int, default=1, help="sequences in the validation split (default 1)")
    p.add_argument("--test", type=int, default=0, help="sequences in the test split (default 0)")
    p.add_argument("--name", default="sim-corpus", help="corpus name (in the manifest and on leaderboards)")
    p.add_argument("--probes", type=_positive_int, default=None,
                   help="HQ frames each alignment fits (default: align's; the demo's one-second views: 8)")
    p.add_argument("--rig", default="lq-hq", help="simulated rig (default lq-hq; multiview4 or multiview4-hq: "
                   "DDD's four-view corpus, one manifest entry per view)")
    p.add_argument("--no-report", dest="reports", action="store_false",
                   help="skip each sequence's alignment report (Markdown and figures)")
    p.add_argument("--motion-model", choices=("edges", "flow"), default=None,
                   help="the references' motion step, as align's (default: flow for lq-hq training corpora, the "
                        "references SSDD trains against; align's default for multi-view rigs)")
    p.add_argument("--reference-edges", default=None, metavar="RULE",
                   help="the references' edge rule, as align's (default: align's)")
    ex = p.add_mutually_exclusive_group()
    ex.add_argument("--jobs", type=_positive_int, metavar="N", help="local processes (default 1)")
    ex.add_argument("--workers", type=_positive_int, metavar="N", help="a local Dask cluster with N workers")
    ex.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask cluster (paths must be shared)")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar on stderr (default: when stderr is a terminal)")
    p.add_argument("--force", action="store_true", help="replace an existing corpus folder")
    p.set_defaults(func=_corpus)


def _corpus(args) -> int:
    from bench.corpus import CorpusSpec, make_corpus
    from bench.executors import ExecutorSpec

    try:
        shifts = tuple(float(x) for x in args.time_shifts_ms.split(",") if x.strip())
    except ValueError:
        raise BenchError(f"--time-shifts-ms {args.time_shifts_ms!r}: expected numbers like -20,35") from None
    spec = CorpusSpec(seeds=args.seeds, scenes=tuple(s.strip() for s in args.scenes.split(",") if s.strip()),
                      seconds=args.seconds, scale=args.scale, time_shifts_ms=shifts, validation=args.validation,
                      test=args.test, name=args.name, rig=args.rig, probes=args.probes, reports=args.reports,
                      motion_model=args.motion_model, reference_edges=args.reference_edges)
    ex = ExecutorSpec(jobs=args.jobs or (None if (args.workers or args.scheduler) else 1), workers=args.workers,
                      scheduler=args.scheduler)
    res = make_corpus(args.out, spec, executor=ex, force=args.force, progress=args.progress)
    print(f"{res.manifest}: {res.sequences} sequences (train/validation/test by sequence)")
    return 0


def _run(args) -> int:
    from bench.metrics import MetricConfig
    from bench.runner import run_benchmark
    from depthbench.fsutil import check_output_outside

    check_output_outside(args.out, args.data, what="results folder")

    config = MetricConfig(radius_m=args.radius_mm / 1000.0)
    res = run_benchmark(args.data, args.methods, args.out, config=config, jobs=args.jobs, workers=args.workers,
                        scheduler=args.scheduler, force=args.force, progress=args.progress, report=not args.no_report,
                        params=_method_params(args.param, allow_train_frames=args.allow_train_frames))
    print(f"{res.table_path}: {len(res.table)} rows ({res.computed} results computed, {res.reused} reused from the "
          "cache)")
    for s in res.superseded:
        print(f"superseded: {s}")
    if res.report is not None:
        print(f"leaderboard: {res.report.markdown}  (HTML: {res.report.html})")
    return 0


def _method_params(items: list[str], *, allow_train_frames: bool = False) -> dict[str, dict]:
    """``["bf.sigma_color=0.02", ...]`` -> ``{"bf": {"sigma_color": 0.02}}`` (values as ``methods run --param``).

    ``allow_train_frames`` adds ``allow_train_frames=true`` to every configured method that has it
    (learned methods: score their own training data, marked in the key and the leaderboard)."""
    from methods.cli import parse_params

    by_method: dict[str, list[str]] = {}
    for item in items:
        method, dot, rest = item.partition(".")
        if not dot or not method.strip() or "=" not in rest:
            raise BenchError(f"--param {item!r}: expected METHOD.NAME=VALUE, e.g. bf.sigma_color=0.02")
        by_method.setdefault(method.strip(), []).append(rest)
    out = {method: parse_params(values) for method, values in by_method.items()}
    if allow_train_frames:
        from methods.registry import available, resolve_name

        for method, values in out.items():
            if "allow_train_frames" in available()[resolve_name(method)].defaults:
                values.setdefault("allow_train_frames", True)
    return out


def _report(args) -> int:
    from bench.report import write_report

    paths = write_report(args.results, n_boot=args.bootstrap, seed=args.seed)
    print(f"leaderboard: {paths.markdown}  (HTML: {paths.html}; {len(paths.figures)} figures)")
    return 0


def _import_ddrnet(args) -> int:
    from align.external import import_ddrnet
    from depthbench.fsutil import check_output_outside

    check_output_outside(args.out, [args.src], what="aligned dataset")

    for p in import_ddrnet(args.src, args.out, force=args.force):
        print(p)
    return 0
