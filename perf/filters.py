"""Timings of the hole-aware classical filters against OpenCV, on one 640x480 depth frame.

    .venv/bin/python perf/filters.py [--sigma-spatial S] [--radius R] [--repeats N] [--check]

Every comparison uses the same window: OpenCV's ``d = 2 * radius + 1`` is our disk of ``radius``
(OpenCV's bilateral filters use that disk too). Targets (issue 5):

* hole-aware bilateral <= 1.5 x ``cv2.bilateralFilter`` (which ignores holes);
* faithful RGF (Gaussian + (iterations - 1) joint passes) <= 1.5 x ``cv2.GaussianBlur`` +
  (iterations - 1) x ``cv2.ximgproc.jointBilateralFilter``;
* and the ratio to ``cv2.ximgproc.rollingGuidanceFilter`` with the same settings.

Runs are interleaved (ours, OpenCV, ours, ...) so load from other processes hits both alike; the
table gives the median and the minimum in milliseconds per frame. ``--check`` exits 1 when a
target is missed (timings on a busy machine are noisy: use it on a quiet one).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from methods import get  # noqa: E402
from methods.base import check_radius  # noqa: E402
from methods.bilateral import bilateral_filter  # noqa: E402
from methods.gaussian import gaussian_filter  # noqa: E402
from methods.joint_bilateral import joint_bilateral_filter  # noqa: E402
from methods.rolling_guidance import rolling_guidance_filter  # noqa: E402
from methods.tools.synthetic import synthetic_scene  # noqa: E402


def _radius(sigma_spatial: float) -> int:
    """The filters' documented default window, ``max(1, ceil(2 * sigma_spatial))``."""
    return check_radius(None, sigma_spatial, method="perf")


def timed(pairs: dict, repeats: int) -> dict:
    """Run every callable ``repeats`` times, interleaved; seconds per call for each."""
    for f in pairs.values():
        f()                                           # warm-up (JIT cache load, OpenCV buffers)
    times = {k: [] for k in pairs}
    for _ in range(repeats):
        for k, f in pairs.items():
            t = time.perf_counter()
            f()
            times[k].append(time.perf_counter() - t)
    return {k: np.array(v) for k, v in times.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    rgf_defaults = get("rolling_guidance").params
    ap.add_argument("--sigma-spatial", type=float, default=float(rgf_defaults["sigma_spatial"]),
                    help="pixels (default: rolling_guidance's swept default)")
    ap.add_argument("--sigma-color", type=float, default=float(rgf_defaults["sigma_color"]), help="metres")
    ap.add_argument("--iterations", type=int, default=int(rgf_defaults["iterations"]))
    ap.add_argument("--radius", type=int, default=None, help="default ceil(2 * sigma_spatial)")
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--check", action="store_true", help="exit 1 when a 1.5x target is missed")
    args = ap.parse_args(argv)
    ss, sr, it = args.sigma_spatial, args.sigma_color, args.iterations
    r = args.radius or _radius(ss)
    d = 2 * r + 1

    truth, depth = synthetic_scene((480, 640), seed=0)
    holes_as_zero = np.nan_to_num(depth, nan=0.0)      # what OpenCV's filters see
    rng = np.random.default_rng(0)
    color = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)
    color_f = color.astype(np.float32)
    sigma_c_rgb = 20.0

    def cv_rgf_parts():
        J = cv2.GaussianBlur(holes_as_zero, (d, d), ss)
        for _ in range(it - 1):
            J = cv2.ximgproc.jointBilateralFilter(J, holes_as_zero, d, sr, ss)
        return J

    import numba
    print(f"640x480 float32 depth, {np.isnan(depth).mean():.1%} holes; sigma_spatial={ss} px, radius={r} "
          f"(OpenCV d={d}), sigma_color={sr} m, iterations={it}; threads: numba {numba.get_num_threads()}, "
          f"OpenCV {cv2.getNumThreads()}; OpenCV {cv2.__version__}")
    rows = []
    groups = [
        ("bilateral (hole-aware)", lambda: bilateral_filter(depth, sigma_spatial=ss, sigma_color=sr, radius=r),
         "cv2.bilateralFilter", lambda: cv2.bilateralFilter(holes_as_zero, d, sr, ss), 1.5, args.repeats),
        ("bilateral, depth-adaptive", lambda: bilateral_filter(depth, sigma_spatial=ss, sigma_color=sr, radius=r,
                                                               depth_adaptive=True),
         "cv2.bilateralFilter", lambda: cv2.bilateralFilter(holes_as_zero, d, sr, ss), None, args.repeats),
        ("joint bilateral, RGB guide", lambda: joint_bilateral_filter(depth, color, sigma_spatial=ss,
                                                                      sigma_color=sigma_c_rgb, radius=r),
         "cv2.ximgproc.jointBilateralFilter (RGB float)",
         lambda: cv2.ximgproc.jointBilateralFilter(color_f, holes_as_zero, d, sigma_c_rgb, ss), None, args.repeats),
        ("gaussian (hole-aware)", lambda: gaussian_filter(depth, sigma_spatial=ss, radius=r),
         "cv2.GaussianBlur", lambda: cv2.GaussianBlur(holes_as_zero, (d, d), ss), None, args.repeats),
        (f"rolling guidance, {it} passes (paper)", lambda: rolling_guidance_filter(
            depth, sigma_spatial=ss, sigma_color=sr, iterations=it, radius=r),
         f"cv2.GaussianBlur + {it - 1} x cv2.ximgproc.jointBilateralFilter", cv_rgf_parts, 1.5, args.repeats),
        (f"rolling guidance, {it} passes (paper)", lambda: rolling_guidance_filter(
            depth, sigma_spatial=ss, sigma_color=sr, iterations=it, radius=r),
         "cv2.ximgproc.rollingGuidanceFilter",
         lambda: cv2.ximgproc.rollingGuidanceFilter(holes_as_zero, d=d, sigmaColor=sr, sigmaSpace=ss, numOfIter=it),
         None, max(3, args.repeats // 3)),
    ]
    ok = True
    for ours_name, ours, cv_name, theirs, target, reps in groups:
        t = timed({"ours": ours, "cv": theirs}, reps)
        mo, mc = np.median(t["ours"]) * 1e3, np.median(t["cv"]) * 1e3
        ratio = mo / mc
        verdict = ""
        if target is not None:
            passed = ratio <= target
            ok &= passed
            verdict = f"{'PASS' if passed else 'FAIL'} (<= {target}x)"
        rows.append((ours_name, mo, np.min(t["ours"]) * 1e3, cv_name, mc, np.min(t["cv"]) * 1e3, ratio, verdict))
    print()
    print("| ours | ms median | ms min | OpenCV | ms median | ms min | ours / OpenCV | target |")
    print("|---|---:|---:|---|---:|---:|---:|---|")
    for name, mo, lo, cvn, mc, lc, ratio, verdict in rows:
        print(f"| {name} | {mo:.1f} | {lo:.1f} | {cvn} | {mc:.1f} | {lc:.1f} | {ratio:.2f} | {verdict} |")
    return 0 if ok or not args.check else 1


if __name__ == "__main__":
    sys.exit(main())
