"""The leaderboard before and after an effect is modelled, on one simulated session.

Aligns the session twice, scores the same methods on both with ``bench run`` (against the HQ
reference and the truth), and prints how each method's error and rank change
(``bench.loop_compare``), and whether the HQ-reference ranking matches the truth's. By default
"before" is ``align`` without the loop and "after" with it (an undeclared effect: ``--effect``);
``--before`` / ``--after KEY=VALUE`` set any option of ``align`` (:class:`align.pipeline.AlignOptions`)
instead, e.g. the reference's own effects: its edges and the motion between unsynchronised frames.

    perf/loop_leaderboard.py --effect distortion_k1=0.1 --seconds 4 --methods raw,bilateral,gaussian
    perf/loop_leaderboard.py --session DEMO --methods raw,bf,jbf,rgf --before reference_edges=strict \
        --after reference_edges=mixed
    perf/loop_leaderboard.py --session P7 --scale 1 --methods raw,bf --before motion_model=edges \
        --after motion_model=flow
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from align.pipeline import align_session
from bench.loop_compare import compare_leaderboards, markdown, rank_agreement
from bench.results import load_results
from bench.runner import run_benchmark
from capture.sim import simulate


def _options(pairs: list[str], default: dict) -> dict:
    """``KEY=VALUE`` strings as :func:`align.pipeline.align_session` keywords (true/false and numbers parsed)."""
    out = dict(default) if not pairs else {}
    for item in pairs:
        key, eq, value = item.partition("=")
        if not eq:
            sys.exit(f"error: align option must be KEY=VALUE, got {item!r}")
        low = value.lower()
        if low in ("true", "false"):
            out[key] = low == "true"
        else:
            try:
                out[key] = float(value) if any(c in value for c in ".e") else int(value)
            except ValueError:
                out[key] = value
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--effect", action="append", default=[])
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--scale", type=float, default=0.5)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--methods", default="raw,bilateral,gaussian")
    ap.add_argument("--work", default="/tmp/depthbench-loop-leaderboard")
    ap.add_argument("--session", default=None, help="use this simulated session instead of simulating one")
    ap.add_argument("--before", action="append", default=[], metavar="KEY=VALUE",
                    help="align option of the 'before' alignment (default: loop=false)")
    ap.add_argument("--after", action="append", default=[], metavar="KEY=VALUE",
                    help="align option of the 'after' alignment (default: loop=true)")
    args = ap.parse_args(argv)
    options = {"before": _options(args.before, {"loop": False}), "after": _options(args.after, {"loop": True})}
    work = Path(args.work)
    session = Path(args.session) if args.session else work / "session"
    if not (session / "session.json").is_file():
        effects = {k: float(v) for k, _, v in (e.partition("=") for e in args.effect)}
        simulate(session, rig="lq-hq", scene="people", seconds=args.seconds, seed=args.seed, scale=args.scale,
                 effects=effects or None, undeclared=True, progress=False, force=True)
    tables = {}
    for tag in ("before", "after"):
        aligned = work / f"aligned_{tag}"
        print(f"{tag}: align {options[tag]}", flush=True)
        align_session(session, aligned, force=True, progress=False, **options[tag])
        res = work / f"results_{tag}"
        run_benchmark([aligned], args.methods, res, force=True, jobs=1, progress=False, report=False)
        tables[tag] = load_results(res)
    table = compare_leaderboards(tables["before"], tables["after"])
    labels = tuple(", ".join(f"{k}={v}" for k, v in options[tag].items()) for tag in ("before", "after"))
    print(markdown(table, labels=labels))
    for metric in ("mse_mm2", "rmse_mm", "mae_mm"):
        agree = rank_agreement(table, metric=metric)
        print(f"{metric}: HQ-reference ranking equals truth ranking -- {labels[0]}: {agree['before']}, "
              f"{labels[1]}: {agree['after']}  ({agree['before_order']} -> {agree['after_order']})")


if __name__ == "__main__":
    main()
