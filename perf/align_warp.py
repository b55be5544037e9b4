"""Warp throughput: HQ depth 512x424 onto the LQ image 640x480 with the z-buffer, one core.

Run:  .venv/bin/python perf/align_warp.py [--session SIM] [--frames 200]

Without ``--session`` it simulates a short lq-hq session (default resolutions) into a temporary
folder and uses its true ``T_lq_hq``. It prints, in one run:

* the warp (:class:`align.warp.DepthWarper`) with its two engines: ``numba`` (the default: numpy
  for the per-point math, one compiled loop for the splat + z-buffer scatter) and ``numpy``
  (vectorised throughout, the scatter through ``np.maximum.at``): frames per second, wall and CPU;
* the straightforward per-pixel loop (:func:`align.warp.warp_depth_naive_loop`: project each HQ
  pixel, round, z-test; no hole filling, no interpolation) on a few frames, and the ratio;
* the machine's load (the suite is developed on a shared machine) and the time of one numpy
  multiply of 217k float32, so numbers from different runs can be compared.

Single-threaded on purpose (OpenCV and BLAS threads set to 1).
"""
from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from align.warp import DepthWarper, warp_depth_naive_loop  # noqa: E402
from capture.session import open_session  # noqa: E402


def _session(path: str | None, tmp: Path) -> Path:
    if path:
        return Path(path)
    from capture.sim import simulate

    root = tmp / "sim"
    simulate(root, rig="lq-hq", scene="people", seconds=0.4, seed=3, progress=False)
    return root


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--session", help="a simulated lq-hq session (default: simulate 0.4 s)")
    ap.add_argument("--frames", type=int, default=200, help="frames to warp (default: %(default)s)")
    ap.add_argument("--loop-frames", type=int, default=2, help="frames for the per-pixel loop (default: %(default)s)")
    args = ap.parse_args()
    cv2.setNumThreads(1)
    with tempfile.TemporaryDirectory() as tmp:
        root = _session(args.session, Path(tmp))
        sess = open_session(root)
        Kh, Kl = sess.intrinsics("hq"), sess.intrinsics("lq")
        try:
            from capture.truth import read_truth

            T = read_truth(root).T_lq_hq
        except Exception:
            T = sess.declared_extrinsics("lq", "hq")
        frames = sess.frames("hq", "depth")["frame_number"].tolist()
        depths = [sess.read_depth("hq", f) for f in frames[:10]]
    a = np.random.rand(217088).astype(np.float32)
    t = time.perf_counter()
    for _ in range(500):
        a * a
    mul_us = (time.perf_counter() - t) / 500 * 1e6
    print(f"machine: load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; numpy multiply of 217k "
          f"float32: {mul_us:.0f} us")
    print(f"HQ depth {Kh.width}x{Kh.height} -> LQ {Kl.width}x{Kl.height}, {len(depths)} distinct frames")
    walls = {}
    for engine in ("numba", "numpy"):
        W = DepthWarper(Kh, Kl, T, engine=engine)
        out = W(depths[0])
        if engine == "numba":
            print(f"  source rows/cols that can reach the LQ image: {tuple(int(x) for x in W.crop)} "
                  f"({np.isfinite(out).mean():.1%} of LQ pixels get a value in frame 0)")
        for _ in range(5):
            W(depths[0])
        t0, c0 = time.perf_counter(), time.process_time()
        for i in range(args.frames):
            W(depths[i % len(depths)])
        wall = (time.perf_counter() - t0) / args.frames
        cpu = (time.process_time() - c0) / args.frames
        walls[engine] = wall
        print(f"z-buffer warp, {engine:5s} engine: {1 / wall:7.1f} frames/s wall ({1e3 * wall:.2f} ms), "
              f"{1 / cpu:7.1f} frames/s CPU ({1e3 * cpu:.2f} ms), {args.frames} frames")
    wall = walls["numba"]
    t0 = time.perf_counter()
    for i in range(args.loop_frames):
        warp_depth_naive_loop(depths[i % len(depths)], Kh, Kl, T)
    loop = (time.perf_counter() - t0) / args.loop_frames
    print(f"straightforward per-pixel loop: {1 / loop:7.3f} frames/s ({loop:.2f} s per frame), {args.loop_frames} frames")
    print(f"speed-up over the loop: numba engine {loop / walls['numba']:.0f}x, numpy engine {loop / walls['numpy']:.0f}x")


if __name__ == "__main__":
    main()
