"""Does the leaderboard against the HQ reference rank methods as the truth does, and if not, why?

Run:  .venv/bin/python perf/reference_ranking.py ALIGNED [--methods raw,bf,rgf] [--frames N]

ALIGNED is an aligned dataset of a simulated session (with its ``truth_depth`` layer, e.g. the
demo's ``aligned/``). Each method runs on the LQ frames and is scored, per frame and inside the
dataset's ROI as ``bench run`` scores it (:func:`bench.metrics.pixel_errors`), six ways:

* against the HQ reference (the leaderboard's first table);
* against the truth (its second table);
* against the truth **on the reference's pixels only** (pixels where the reference has depth);
* against the truth on the ROI pixels **without** a reference (the ROI takes the LQ depth there:
  HQ sensor holes, the gap past a surface's last HQ sample, occlusion shadows, the edge rule's mask);
* against the reference and against the truth on the reference's pixels **away from its own depth edges**
  (:func:`bench.masks.interior_strata`: the order the leaderboard ranks by since session 13).

For every pair of methods it prints the mean over frames of the per-frame difference in MSE and
RMSE, with a 95 % bootstrap interval over frames (2000 resamples), in each of the six scorings.
Where the reference and the truth disagree on a pair's order but the truth on the reference's pixels
agrees with the reference, the reference's values are not to blame: the pixels it leaves out (edges,
where the HQ sensor cannot say which surface is there) are where the two methods differ. Issue 12's
demo, BF against RGF, is such a pair (the closing note of session 5): on the demo of session 8, 60
frames, BF - RGF MSE against the reference +4.6 [+3.3, +6.0] mm², against the truth -15.5 [-21.2, -9.9],
on the reference's pixels +6.4 [+5.2, +7.7], with every edge rule (``strict``, ``strict-fg``, ``mixed``,
``mixed-fg``); the fourth scoring shows where the truth's order comes from. It also prints the order of the
methods in each scoring and whether the reference's equals the truth's.

Since session 9 the leaderboard itself scores the truth columns on the reference's pixels and reports the rest
of the ROI as the stratum "silhouettes / no reference", with the same check (:func:`bench.summary.ranking_check`);
this script recomputes it from the aligned dataset alone, methods run afresh.
"""
from __future__ import annotations

import argparse
import itertools

import numpy as np

from align.dataset import AlignedDataset
from bench.masks import interior_strata
from bench.metrics import pixel_errors
from methods.registry import get

SCORINGS = ("reference", "truth", "truth on reference pixels", "truth on pixels without reference",
            "reference away from its edges", "truth away from reference edges")


def _scores(ds: AlignedDataset, methods: list[str], frames: list[int]) -> dict:
    """method -> scoring -> (n_frames, 2) array of (MSE mm², RMSE mm)."""
    runners = {m: get(m) for m in methods}
    out = {m: {s: [] for s in SCORINGS} for m in methods}
    for i in frames:
        f = ds.frame(i)
        has = np.isfinite(f.reference)
        refs = {"reference": f.reference, "truth": f.truth,
                "truth on reference pixels": np.where(has, f.truth, np.float32(np.nan)),
                "truth on pixels without reference": np.where(has, np.float32(np.nan), f.truth)}
        inner = interior_strata(f.reference, f.truth)
        refs.update({"reference away from its edges": inner["hq_interior"],
                     "truth away from reference edges": inner["truth_interior"]})
        for m, r in runners.items():
            pred = r.denoise(f.lq_depth, f.lq_color, camera=ds.lq_intrinsics)
            for s, ref in refs.items():
                e = pixel_errors(pred, ref, f.roi)
                out[m][s].append((e["mse_mm2"], e["rmse_mm"]))
    return {m: {s: np.array(v) for s, v in d.items()} for m, d in out.items()}


def _interval(x: np.ndarray, rng: np.random.Generator) -> str:
    boot = x[rng.integers(0, x.size, (2000, x.size))].mean(axis=1)
    lo, hi = np.percentile(boot, [2.5, 97.5])
    return f"{x.mean():+8.2f} [{lo:+.2f}, {hi:+.2f}]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("aligned", help="aligned dataset of a simulated session (with truth_depth)")
    ap.add_argument("--methods", default="raw,bf,rgf", help="comma-separated methods (default: %(default)s)")
    ap.add_argument("--frames", type=int, default=0, help="score every k-th frame so that about N are used (0: all)")
    args = ap.parse_args()
    ds = AlignedDataset(args.aligned)
    n = len(ds)
    frames = list(range(n)) if args.frames <= 0 else list(range(0, n, max(1, n // args.frames)))
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    sc = _scores(ds, methods, frames)
    print(f"{ds.name}: {len(frames)} frames; mean over frames (MSE mm² / RMSE mm)")
    for s in SCORINGS:
        print(f"  against {s:34s} " + "  ".join(f"{m} {np.nanmean(sc[m][s][:, 0]):8.1f} / {np.nanmean(sc[m][s][:, 1]):6.2f}"
                                                 for m in methods))
    for k, metric in enumerate(("MSE", "RMSE")):
        order = {s: sorted(methods, key=lambda m: np.nanmean(sc[m][s][:, k])) for s in SCORINGS}
        same = order["reference"] == order["truth"]
        inner = order["reference away from its edges"] == order["truth away from reference edges"]
        print(f"  order by {metric:4s}: " + " | ".join(f"{s}: {' < '.join(o)}" for s, o in order.items())
              + f"  -> reference ranks as the truth: {'yes' if same else 'NO'}; away from its edges: "
              f"{'yes' if inner else 'NO'}")
    rng = np.random.default_rng(0)
    print("paired differences, mean over frames [95 % bootstrap]; order: '<' first method better")
    for a, b in itertools.combinations(methods, 2):
        for k, metric in enumerate(("MSE", "RMSE")):
            cells = []
            for s in SCORINGS:
                d = sc[a][s][:, k] - sc[b][s][:, k]
                d = d[np.isfinite(d)]
                cells.append(f"{s}: {_interval(d, rng)} {'<' if d.mean() < 0 else '>'}")
            print(f"  {a}-{b} {metric:4s} | " + " | ".join(cells))


if __name__ == "__main__":
    main()
