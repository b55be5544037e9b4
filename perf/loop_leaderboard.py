"""The leaderboard with and without the alignment loop, on one simulated session with an undeclared effect.

Aligns the session twice (``loop=False`` / ``loop=True``), scores the same methods on both with
``bench run`` (against the HQ reference and the truth), and prints how each method's error and
rank change (``bench.loop_compare``), and whether the HQ-reference ranking matches the truth's.

    perf/loop_leaderboard.py --effect distortion_k1=0.1 --seconds 4 --methods raw,bilateral,gaussian
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


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--effect", action="append", default=[])
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--scale", type=float, default=0.5)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--methods", default="raw,bilateral,gaussian")
    ap.add_argument("--work", default="/tmp/depthbench-loop-leaderboard")
    ap.add_argument("--session", default=None, help="use this simulated session instead of simulating one")
    args = ap.parse_args(argv)
    work = Path(args.work)
    session = Path(args.session) if args.session else work / "session"
    if not (session / "session.json").is_file():
        effects = {k: float(v) for k, _, v in (e.partition("=") for e in args.effect)}
        simulate(session, rig="lq-hq", scene="people", seconds=args.seconds, seed=args.seed, scale=args.scale,
                 effects=effects or None, undeclared=True, progress=False, force=True)
    tables = {}
    for tag, loop in (("before", False), ("after", True)):
        aligned = work / f"aligned_{tag}"
        align_session(session, aligned, force=True, progress=False, loop=loop)
        res = work / f"results_{tag}"
        run_benchmark([aligned], args.methods, res, force=True, jobs=1, progress=False, report=False)
        tables[tag] = load_results(res)
    table = compare_leaderboards(tables["before"], tables["after"])
    print(markdown(table))
    for metric in ("mse_mm2", "rmse_mm", "mae_mm"):
        agree = rank_agreement(table, metric=metric)
        print(f"{metric}: HQ-reference ranking equals truth ranking -- without the loop {agree['before']}, "
              f"with it {agree['after']}  ({agree['before_order']} -> {agree['after_order']})")


if __name__ == "__main__":
    main()
