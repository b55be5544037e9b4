"""The classical filters re-scored on held-out simulated sessions, before and after a simulator change.

    .venv/bin/python perf/filters_rescore.py [--work DIR] [--seed 13] [--variants people-boxy people people:D415]

Each variant is ``SCENE`` or ``SCENE:LQ_PROFILE`` (a measured sensor profile, ``capture simulate
--lq-profile``). For each, the sweep's held-out set-up (``methods/tools/sweep_defaults.py``:
``lq-hq`` rig, 3 s at 2 frames/s, seed 13) is simulated once (cached in ``--work``) and raw depth
and every classical filter with its swept defaults (``methods/defaults.json``) are scored against
the LQ noise-free truth on the pixels where the raw depth exists and the true depth is 1-3 m:

* MSE (mm^2) and MAE (mm), pooled over the frames;
* plane-fit RMSE (mm): DDD's metric (``bench.plane_fit.plane_fit_rmse``) against the truth's
  local planes in the same pixels, pooled over frames (RMS of the per-frame RMSEs weighted by
  their pixels).

95 % intervals: bootstrap over frames (1000 resamples). The filters run without hole filling,
so every method is scored on the raw depth's own pixels. Tables in Markdown on stdout.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from methods._defaults import swept  # noqa: E402
from methods.tools.sweep_defaults import SECONDS, FPS, Z_RANGE_M, run  # noqa: E402

METHODS = ("raw", "gaussian", "bilateral", "joint_bilateral", "rolling_guidance")


def frames_of(variant: str, seed: int, work: Path):
    """``(lq_depth, lq_color, lq_truth)`` per LQ frame of ``variant``'s session, and the LQ intrinsics."""
    from capture.session import open_session
    from capture.sim.simulator import simulate
    from capture.truth import read_truth

    scene, _, profile = variant.partition(":")
    root = work / f"{variant.replace(':', '_').replace(' ', '_')}_seed{seed}"
    if not (root / "session.json").exists():
        print(f"simulating {root} ...", file=sys.stderr)
        simulate(root, rig="lq-hq", scene=scene, seconds=SECONDS, seed=seed, lq_fps=FPS, hq_fps=FPS, force=True,
                 progress=False, lq_profile=profile or None)
    session, truth = open_session(root), read_truth(root)
    frames = [(session.read_depth("lq", int(n)), session.read_color("lq", int(n)), truth.depth("lq", int(n)))
              for n in session.frames("lq", "depth")["frame_number"]]
    return frames, session.intrinsics("lq", "depth")


def per_frame_sums(outputs, frames, K) -> np.ndarray:
    """``(F, 5)``: per frame n, sum e^2, sum |e| (m), plane-fit pixels and their sum of squared distances."""
    from bench.plane_fit import plane_fit_rmse

    rows = []
    for out, (d, _, z) in zip(outputs, frames):
        m = np.isfinite(d) & np.isfinite(z) & (z >= Z_RANGE_M[0]) & (z <= Z_RANGE_M[1])
        e = (out[m] - z[m]).astype(np.float64)
        pf = plane_fit_rmse(np.where(m, out, np.nan), np.where(m, z, np.nan), K, roi=m)
        dist = pf.distance_m[np.isfinite(pf.distance_m)]
        rows.append((m.sum(), e @ e, np.abs(e).sum(), dist.size, float(dist @ dist)))
    return np.asarray(rows, np.float64)


def metrics(sums: np.ndarray) -> np.ndarray:
    """MSE mm^2, MAE mm, plane-fit RMSE mm of pooled per-frame sums."""
    s = sums.sum(axis=0)
    return np.array([1e6 * s[1] / s[0], 1e3 * s[2] / s[0], 1e3 * np.sqrt(s[4] / s[3])])


def bootstrap(sums: np.ndarray, *, n: int = 1000, seed: int = 0) -> np.ndarray:
    """``(2, 3)`` 95 % interval of :func:`metrics` over frames resampled with replacement."""
    rng = np.random.default_rng(seed)
    draws = np.array([metrics(sums[rng.integers(0, len(sums), len(sums))]) for _ in range(n)])
    return np.percentile(draws, [2.5, 97.5], axis=0)


def table(variant: str, frames, K) -> list[str]:
    lines = [f"### {variant}: {len(frames)} frames", "",
             "| method | MSE mm² [95 %] | MAE mm [95 %] | plane-fit RMSE mm [95 %] |", "|---|---:|---:|---:|"]
    for method in METHODS:
        params = {} if method == "raw" else swept(method)
        sums = per_frame_sums(run(method, params, frames), frames, K)
        v, ci = metrics(sums), bootstrap(sums)
        cells = [f"{v[i]:.{p}f} [{ci[0, i]:.{p}f}, {ci[1, i]:.{p}f}]" for i, p in ((0, 0), (1, 2), (2, 2))]
        lines.append(f"| {method} | " + " | ".join(cells) + " |")
    return lines + [""]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--work", default="out/filters_rescore", help="cache of simulated sessions")
    ap.add_argument("--seed", type=int, default=13, help="held-out seed (the sweep's: 13)")
    ap.add_argument("--variants", nargs="+", default=["people-boxy", "people"], help="SCENE or SCENE:LQ_PROFILE")
    args = ap.parse_args()
    t0 = time.perf_counter()
    for variant in args.variants:
        frames, K = frames_of(variant, args.seed, Path(args.work))
        print("\n".join(table(variant, frames, K)), flush=True)
    print(f"defaults: {', '.join(f'{m} {swept(m)}' for m in METHODS[1:])}; {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
