"""Power and false-alarm study of the alignment loop (align.loop) on simulated lq-hq sessions.

For each seed: simulate a session (cached under --cache), fit the base model (``fit_pair``,
never truth), run the loop, and compare what it added with the truth. Prints one row per
configuration: how often each effect was added (with a Wilson 95 % interval), the parameter
estimates against the truth (and whether the interval covered it), the held-out error before
and after, and where the loop's time went. Clean sessions give the false-alarm rate (with the
one-sided 95 % upper bound when none occurs: ``1 - 0.05^(1/n)``). A session whose base fit fails
(``DepthbenchError``: e.g. a drawn time shift so near the end of the +-60 ms range that its estimate
falls in the edge band) is reported and left out of the rates.

    perf/loop_study.py                                                    # formula probes, clean, seeds 0-19
    perf/loop_study.py --simulated --seeds 100-119 --seconds 3            # clean: false alarms
    perf/loop_study.py --simulated --seeds 100-103 --effect rolling_shutter_ms=10     # small size: power
    perf/loop_study.py --simulated --seeds 11 --seconds 30 --scale 1                  # timing of a 30 s session
    perf/loop_study.py --seeds 0-49 --effect k1=0.02                                  # formula probes: power
    perf/loop_study.py --summarise a.jsonl b.jsonl                        # the summary of saved rows, pooled

Without ``--simulated`` the study runs the feature phase on probes made by formula (``align.loop.synthetic``:
no renderer, no feature tracker): cheap enough for many seeds; effects ``drift_ppm``,
``readout_ms``, ``k1``, ``hq_k1``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from align.loop.effects.frames import drop_interval
from align.loop.loop import LoopOptions
from align.loop.run import close_loop
from align.pipeline import AlignOptions, fit_pair, pair_setup
from bench.cli import parse_seeds
from capture.session import open_session
from capture.sim import simulate
from depthbench.errors import DepthbenchError

#: simulator effect -> (loop effect, parameter, conversion of the simulator value)
EXPECT = {
    "clock_drift_ppm": ("clock_drift", "b_ppm", lambda v: v),
    "rolling_shutter_ms": ("rolling_shutter_lq", "readout_ms", lambda v: v),
    "distortion_k1": ("lens_lq_k1", "k1", lambda v: v),
    "hq_distortion_k1": ("lens_hq_k1", "k1", lambda v: v),
    "depth_scale": ("depth_scale", "scale", lambda v: v),
    "depth_offset_mm": ("depth_offset", "offset_mm", lambda v: v),
    "frame_duplicate_rate": ("duplicated_frames", "rate", lambda v: v),
}


def run_one(seed: int, effects: dict, args) -> dict:
    tag = "clean" if not effects else "+".join(f"{k}={v:g}" for k, v in sorted(effects.items()))
    root = Path(args.cache) / f"{tag}-s{seed}-{args.seconds:g}s-x{args.scale:g}"
    t0 = time.perf_counter()
    if not (root / "session.json").is_file():
        simulate(root, rig="lq-hq", scene="people", seconds=args.seconds, seed=seed, scale=args.scale,
                 effects=effects or None, undeclared=True, progress=False, force=True)
    t_sim = time.perf_counter() - t0
    setup = pair_setup(open_session(root), lq="lq", hq="hq")
    t1, c1 = time.perf_counter(), time.process_time()
    pf = fit_pair(setup, AlignOptions(progress=False, detect_scale=args.detect_scale))
    t_fit, c_fit = time.perf_counter() - t1, time.process_time() - c1
    loop = close_loop(setup, pf, options=LoopOptions(replicates=args.replicates))
    found = {f.name: f.to_dict() for f in loop.findings if f.source == "found"}
    return {"seed": seed, "effects": effects, "found": found, "seconds": {"simulate": t_sim, "fit": t_fit, "cpu_fit": c_fit,
                                                                          **loop.seconds},
            "heldout_px": [loop.features.heldout_before.get("median_abs"), loop.features.heldout_after.get("median_abs")],
            "heldout_depth": None if loop.depth is None else [loop.depth.heldout_before["median_abs"],
                                                               loop.depth.heldout_after["median_abs"]],
            "threshold": loop.features.threshold, "unexplained": [s.name for s in loop.unexplained()],
            "stages": _stages(loop.features.stages) + ([] if loop.depth is None else _stages(loop.depth.stages))}


def _stages(stages) -> list[dict]:
    """Each stage's candidates as ``{name: [z, delta_bic, held-out improvement]}`` (look-alike confusion)."""
    return [{"accepted": s.accepted, "undone": s.undone,
             "candidates": {n: [c.z, c.delta_bic, c.improvement] for n, c in s.candidates.items()}}
            for s in stages]


SYNTH_EXPECT = {"drift_ppm": ("clock_drift", "b_ppm"), "readout_ms": ("rolling_shutter_lq", "readout_ms"),
                "k1": ("lens_lq_k1", "k1"), "hq_k1": ("lens_hq_k1", "k1")}


def run_synthetic(seed: int, effects: dict, args) -> dict:
    from align.loop.loop import fit_feature_effects
    from align.loop.synthetic import feature_data, start

    fd, truth = feature_data(seed=seed, seconds=args.seconds, **effects)
    T, a = start(truth, rng_seed=seed + 1)
    t0, c0 = time.perf_counter(), time.process_time()
    fl = fit_feature_effects(fd, T=T, shift_us=a, options=LoopOptions(replicates=args.replicates, seed=seed))
    return {"seed": seed, "effects": effects, "found": {f.name: f.to_dict() for f in fl.findings if f.source == "found"},
            "seconds": {"total": time.perf_counter() - t0, "cpu_total": time.process_time() - c0,
                        **{f"features.{k}": v for k, v in fl.seconds.items()}},
            "heldout_px": [fl.heldout_before.get("median_abs"), fl.heldout_after.get("median_abs")],
            "heldout_depth": None, "threshold": fl.threshold, "unexplained": [s.name for s in fl.after if s.structured],
            "synthetic": True}


def _coverage(est: list[dict], param: str, truth: float) -> None:
    """RMS of error/std and the share of 95 % intervals covering the truth; where a finding carries a
    model error, the same for the fit's own deviation (``std_fit``) beside it."""
    if not est:
        return
    err = np.array([d["params"][param] - truth for d in est])
    for label, key in (("stated", "std"), ("fit alone", "std_fit")):
        sd = np.array([(d.get(key) or {}).get(param, np.nan) for d in est], float)
        if not np.all(np.isfinite(sd)):
            continue
        z = err / sd
        print(f"    {param}, {label} deviation: RMS error/std {np.sqrt(np.mean(z ** 2)):.2f}, "
              f"intervals covering {int(np.sum(np.abs(z) < 1.96))} of {z.size}, RMS error {np.sqrt(np.mean(err ** 2)):.4g}")


def summarise(rows: list[dict]) -> None:
    n = len(rows)
    eff = rows[0]["effects"] if rows else {}
    print(f"\nconfiguration: {eff or 'clean'}   sessions: {n}")
    names = sorted({k for r in rows for k in r["found"]})
    if not names:
        print(f"  nothing added in {n} of {n}: false-alarm rate 0, 95 % upper bound {1 - 0.05 ** (1 / max(n, 1)):.3f}")
    for name in names:
        k = sum(name in r["found"] for r in rows)
        p, lo, hi = drop_interval(k, n)
        print(f"  {name:22s} added in {k:2d} of {n}: rate {p:.2f} [{lo:.2f}, {hi:.2f}]")
    for sim_name, v in eff.items():
        if rows and rows[0].get("synthetic"):
            loop_name, param = SYNTH_EXPECT.get(sim_name, (None, None))
            conv = (lambda x: x)
        else:
            loop_name, param, conv = EXPECT.get(sim_name, (None, None, None))
        if loop_name is None:
            continue
        truth = conv(v)
        est = [r["found"][loop_name] for r in rows if loop_name in r["found"]]
        for d in est:
            iv = d.get("interval95", {}).get(param)
            val = d["params"][param]
            cover = iv is not None and iv[0] <= truth <= iv[1]
            print(f"    {loop_name}.{param}: truth {truth:g}, estimate {val:.4g} {iv and [round(x, 4) for x in iv]}, "
                  f"error {100 * (val - truth) / truth:+.1f} %, interval covers: {cover}")
        _coverage(est, param, truth)
    hb = [r["heldout_px"][0] for r in rows]
    ha = [r["heldout_px"][1] for r in rows]
    print(f"  held-out feature residual, median abs px: before {np.mean(hb):.3f}, after {np.mean(ha):.3f}")
    hd = [r["heldout_depth"] for r in rows if r["heldout_depth"]]
    if hd:
        print(f"  held-out depth residual, median abs %: before {100 * np.mean([h[0] for h in hd]):.3f}, "
              f"after {100 * np.mean([h[1] for h in hd]):.3f}")
    secs = {k: np.mean([r["seconds"].get(k, 0.0) for r in rows]) for k in
            ("simulate", "fit", "cpu_fit", "total", "cpu_total", "features", "features.base_fit", "features.bootstrap", "features.final",
             "depth", "frames")}
    print("  seconds (mean): " + ", ".join(f"{k} {v:.1f}" for k, v in secs.items()))
    print(f"  unexplained signatures: {sorted({u for r in rows for u in r['unexplained']})}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-19")
    ap.add_argument("--effect", action="append", default=[], help="NAME=VALUE (simulator effect, undeclared)")
    ap.add_argument("--seconds", type=float, default=None, help="session length (default 3 s simulated, 8 s formula)")
    ap.add_argument("--scale", type=float, default=0.5)
    ap.add_argument("--replicates", type=int, default=100)
    ap.add_argument("--cache", default="/tmp/depthbench-loop-study")
    ap.add_argument("--detect-scale", type=float, default=None,
                    help="align's feature detection scale (default: align's own choice)")
    ap.add_argument("--jsonl", default=None, help="append every session's result to this file")
    ap.add_argument("--simulated", action="store_true", help="rendered lq-hq sessions and the whole loop (slow)")
    ap.add_argument("--summarise", nargs="+", default=None, metavar="JSONL",
                    help="print the summary of rows saved with --jsonl (one configuration) and run nothing")
    args = ap.parse_args(argv)
    if args.summarise:
        rows = [json.loads(line) for p in args.summarise for line in Path(p).read_text().splitlines() if line.strip()]
        for r in rows:
            if "failed" in r:
                print(f"seed {r['seed']}: failed before the loop ({r['failed']}); not counted")
        summarise([r for r in rows if "failed" not in r])
        return
    effects = {k: float(v) for k, _, v in (e.partition("=") for e in args.effect)}
    args.synthetic = not args.simulated
    if args.seconds is None:
        args.seconds = 8.0 if args.synthetic else 3.0
    rows = []
    for seed in parse_seeds(args.seeds):
        try:
            row = run_synthetic(seed, effects, args) if args.synthetic else run_one(seed, effects, args)
        except DepthbenchError as exc:  # e.g. the base fit's shift on the edge of its range: no loop to study
            print(f"seed {seed}: failed before the loop: {type(exc).__name__}: {exc}", flush=True)
            row = {"seed": seed, "effects": effects, "failed": f"{type(exc).__name__}: {exc}"}
            if args.jsonl:
                with open(args.jsonl, "a") as f:
                    f.write(json.dumps(row) + "\n")
            continue
        rows.append(row)
        print(f"seed {seed}: added {sorted(row['found']) or 'nothing'}  ({row['seconds']['total']:.1f} s loop, "
              f"{row['seconds'].get('cpu_total', float('nan')):.1f} s CPU)",
              flush=True)
        if args.jsonl:
            with open(args.jsonl, "a") as f:
                f.write(json.dumps(row, default=float) + "\n")
    summarise(rows)


if __name__ == "__main__":
    main()
