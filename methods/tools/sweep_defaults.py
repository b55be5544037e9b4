"""Choose the classical filters' default parameters on simulated people at 1-3 m.

    .venv/bin/python -m methods.tools.sweep_defaults [--work DIR] [--write]

1. Simulates ``lq-hq`` sessions of the ``people`` scene (``capture.sim.simulate``): seeds 11 and 12
   to tune, seed 13 held out; 3 s each at 2 frames/s, so frames are half a second apart.
2. Scores the LQ depth against the LQ noise-free truth directly (``capture.truth``; no alignment
   needed): pooled RMSE and mean absolute error in millimetres over the pixels where the LQ
   sensor gave a depth and the true depth is 1-3 m (the people's range; floor and props at that
   range count too). Filters run without hole filling, so every method is scored on the raw
   depth's own pixels.
3. Grid-searches each filter on the tuning frames (lowest RMSE wins), then reports raw and every
   chosen filter on the held-out frames.

Writes ``methods/defaults_sweep.md`` (the table that justifies the defaults) and, with
``--write``, ``methods/defaults.json``. Simulated sessions are cached in ``--work``.
"""
from __future__ import annotations

import argparse
import itertools
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from methods._defaults import DEFAULTS_PATH
from methods.bilateral import bilateral_filter
from methods.gaussian import gaussian_filter
from methods.joint_bilateral import joint_bilateral_filter
from methods.rolling_guidance import rolling_guidance_filter

REPO = Path(__file__).resolve().parents[2]
TABLE_PATH = REPO / "methods" / "defaults_sweep.md"
TUNE_SEEDS = (11, 12)
HELD_OUT_SEEDS = (13,)
SECONDS, FPS = 3.0, 2.0
Z_RANGE_M = (1.0, 3.0)

GRIDS = {
    "gaussian": dict(sigma_spatial=[0.5, 0.75, 1.0, 1.5, 2.0, 3.0]),
    "bilateral": dict(sigma_spatial=[1.0, 1.5, 2.0, 3.0, 4.0, 5.0],
                      sigma_color=[0.005, 0.01, 0.02, 0.03, 0.05, 0.08, 0.12],
                      depth_adaptive=[False, True]),
    "joint_bilateral": dict(sigma_spatial=[0.75, 1.0, 1.5, 2.0, 3.0, 4.0],
                            sigma_color=[1.0, 2.0, 3.0, 5.0, 10.0, 20.0, 40.0, math.inf]),
    # iterations are scored along one run (J^2, J^3, ... are the intermediate results)
    "rolling_guidance": dict(sigma_spatial=[1.5, 2.0, 3.0, 4.0], sigma_color=[0.01, 0.02, 0.03, 0.05, 0.08],
                             depth_adaptive=[False, True], iterations=[2, 3, 4, 5, 6]),
}
FILTERS = {"gaussian": gaussian_filter, "bilateral": bilateral_filter, "rolling_guidance": rolling_guidance_filter}


# ----------------------------------------------------------------------------- data
def frames_of(seed: int, work: Path) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """``(lq_depth, lq_color, lq_truth)`` of every LQ frame of the simulated session ``seed``."""
    from capture.session import open_session
    from capture.sim.simulator import simulate
    from capture.truth import read_truth

    root = work / f"people_seed{seed}"
    if not (root / "session.json").exists():
        print(f"simulating {root} ...", file=sys.stderr)
        simulate(root, rig="lq-hq", scene="people", seconds=SECONDS, seed=seed, lq_fps=FPS, hq_fps=FPS,
                 force=True, progress=False)
    session, truth = open_session(root), read_truth(root)
    out = []
    for fn in session.frames("lq", "depth")["frame_number"]:
        out.append((session.read_depth("lq", int(fn)), session.read_color("lq", int(fn)), truth.depth("lq", int(fn))))
    return out


class Scorer:
    """Pooled squared and absolute errors (metres) over the scored pixels of a list of frames."""

    def __init__(self, frames):
        self.frames = frames
        self.masks = [np.isfinite(d) & np.isfinite(z) & (z >= Z_RANGE_M[0]) & (z <= Z_RANGE_M[1])
                      for d, _, z in frames]
        self.n = int(sum(m.sum() for m in self.masks))

    def score(self, outputs) -> tuple[float, float]:
        se = ae = 0.0
        for out, m, (_, _, z) in zip(outputs, self.masks, self.frames):
            e = (out[m] - z[m]).astype(np.float64)
            if not np.isfinite(e).all():
                raise RuntimeError("a filter left NaN on a scored pixel")
            se += float(e @ e)
            ae += float(np.abs(e).sum())
        return 1e3 * math.sqrt(se / self.n), 1e3 * ae / self.n


def run(method: str, params: dict, frames) -> list[np.ndarray]:
    if method == "raw":
        return [d for d, _, _ in frames]
    if method == "joint_bilateral":
        return [joint_bilateral_filter(d, c, **params) for d, c, _ in frames]
    return [FILTERS[method](d, **params) for d, _, _ in frames]


def sweep(method: str, scorer: Scorer) -> list[tuple[dict, float, float]]:
    grid = dict(GRIDS[method])
    results = []
    if method == "rolling_guidance":
        its = grid.pop("iterations")
        for combo in itertools.product(*grid.values()):
            p = dict(zip(grid, combo))
            # one run to max(its) passes, scoring the iterate after each pass in its
            Js = {}
            for d, _, _ in scorer.frames:
                J = None
                for it in range(1, max(its) + 1):
                    J = _rgf_step(d, J, p)
                    if it in its:
                        Js.setdefault(it, []).append(_holes(J, d))
            for it in its:
                rmse, mae = scorer.score(Js[it])
                results.append(({**p, "iterations": it}, rmse, mae))
        return results
    for combo in itertools.product(*grid.values()):
        p = dict(zip(grid, combo))
        rmse, mae = scorer.score(run(method, p, scorer.frames))
        results.append((p, rmse, mae))
    return results


def _rgf_step(depth, J, p):
    """One pass of the rolling guidance filter (eq. 10 for the first, eq. 11 after), as the method runs it."""
    from methods._kernels import gaussian_mean, joint_mean
    from methods.base import check_radius
    from methods.bilateral import range_coefficient
    r = check_radius(None, p["sigma_spatial"], method="sweep")
    if J is None:
        return gaussian_mean(depth, sigma_spatial=p["sigma_spatial"], radius=r)
    coef = range_coefficient(J, p["sigma_color"], depth_adaptive=p["depth_adaptive"], z_ref=2.0)
    return joint_mean(depth, J, coef, sigma_spatial=p["sigma_spatial"], radius=r, ref=J)


def _holes(J, depth):
    J = J.copy()
    J[~np.isfinite(depth)] = np.nan
    return J


def _fmt_params(p: dict) -> str:
    return ", ".join(f"{k}={'inf' if isinstance(v, float) and math.isinf(v) else v}" for k, v in p.items())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", default=str(REPO / "out" / "sweep_defaults"), help="cache of simulated sessions")
    ap.add_argument("--write", action="store_true", help="write methods/defaults.json with the winners")
    ap.add_argument("--table", default=str(TABLE_PATH), help="markdown report (default methods/defaults_sweep.md)")
    args = ap.parse_args(argv)
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    tune = [f for s in TUNE_SEEDS for f in frames_of(s, work)]
    held = [f for s in HELD_OUT_SEEDS for f in frames_of(s, work)]
    tune_s, held_s = Scorer(tune), Scorer(held)
    raw_tune = tune_s.score(run("raw", {}, tune))

    lines = ["# Default parameters of the classical filters: the sweep", "",
             "Generated by `.venv/bin/python -m methods.tools.sweep_defaults --write` "
             "(`methods/tools/sweep_defaults.py`); do not edit by hand.", "",
             f"Data: simulated `lq-hq` rig, `people` scene, {SECONDS:g} s at {FPS:g} frames/s per seed; "
             f"tuning seeds {', '.join(map(str, TUNE_SEEDS))} ({len(tune)} frames, {tune_s.n} scored pixels), "
             f"held-out seed {', '.join(map(str, HELD_OUT_SEEDS))} ({len(held)} frames, {held_s.n} pixels). "
             f"Score: LQ depth against the LQ noise-free truth on pixels with an LQ depth and a true depth of "
             f"{Z_RANGE_M[0]:g}-{Z_RANGE_M[1]:g} m; RMSE and mean absolute error in mm, pooled over frames. "
             "Filters run without hole filling, so they are scored on exactly the raw depth's pixels. "
             "The window radius is the default ceil(2 sigma_spatial); z_ref = 2 m for depth_adaptive.", "",
             f"Raw LQ depth on the tuning frames: RMSE {raw_tune[0]:.2f} mm, MAE {raw_tune[1]:.2f} mm.", ""]
    chosen = {}
    for method in GRIDS:
        t0 = time.perf_counter()
        res = sorted(sweep(method, tune_s), key=lambda r: r[1])
        chosen[method] = res[0][0]
        print(f"{method}: {len(res)} settings in {time.perf_counter() - t0:.0f} s; best {_fmt_params(res[0][0])} "
              f"RMSE {res[0][1]:.2f} mm (raw {raw_tune[0]:.2f})", file=sys.stderr)
        shown = res if len(res) <= 13 else res[:10] + [None] + res[-3:]
        lines += [f"## {method}: {len(res)} settings, {'all' if len(res) <= 13 else 'best 10 and worst 3'} "
                  "(tuning frames)", "", "| parameters | RMSE mm | MAE mm |", "|---|---:|---:|"]
        for row in shown:
            lines.append("| ... | | |" if row is None else f"| {_fmt_params(row[0])} | {row[1]:.2f} | {row[2]:.2f} |")
        lines.append("")
        if res[0][1] >= raw_tune[0]:
            lines += [f"No setting of {method} beats the raw depth's RMSE ({raw_tune[0]:.2f} mm): it blurs depth "
                      "edges. The least harmful setting is kept as its default.", ""]

    raw_h = held_s.score(run("raw", {}, held))
    lines += ["## Held-out frames: raw depth and every filter with its chosen defaults", "",
              "| method | defaults | RMSE mm | MAE mm | RMSE vs raw | MAE vs raw |", "|---|---|---:|---:|---:|---:|",
              f"| raw | | {raw_h[0]:.2f} | {raw_h[1]:.2f} | | |"]
    for method, p in chosen.items():
        rmse, mae = held_s.score(run(method, p, held))
        lines.append(f"| {method} | {_fmt_params(p)} | {rmse:.2f} | {mae:.2f} | "
                     f"{100 * (rmse / raw_h[0] - 1):+.1f} % | {100 * (mae / raw_h[1] - 1):+.1f} % |")
    lines += ["", f"Sweep time: {time.perf_counter() - started:.0f} s.", ""]
    text = "\n".join(lines)
    Path(args.table).write_text(text)
    print(text)
    if args.write:
        defaults = json.loads(DEFAULTS_PATH.read_text())
        for method, p in chosen.items():
            defaults[method] = {k: ("inf" if isinstance(v, float) and math.isinf(v) else v) for k, v in p.items()}
        DEFAULTS_PATH.write_text(json.dumps(defaults, indent=2) + "\n")
        print(f"wrote {DEFAULTS_PATH}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
