"""Timing: DDD's plane-fit RMSE of one 640x480 frame, fast path against per-point brute force, same run.

    .venv/bin/python perf/plane_fit.py [--threads 2] [--repeats 15] [--subset 2000]

Frames:
  * ``synthetic``: a full 640x480 frame (every pixel valid) of a room-like scene at 1-3.2 m, HQ
    noise 1 mm, LQ noise 1.5 mm x z^2 (stereo-like): the worst case, every pixel scored;
  * ``ddrnet``: frame 1 of ../shared/data/real/ddrnet_person/group1 (raw against the fused
    reference inside the person mask, ~20 % of the pixels), when that folder exists.

Each frame is timed with ``bench.metrics.plane_fit_rmse`` (grid search, and the KD-tree variant)
on ``--threads`` threads: wall-clock minimum and median over ``--repeats`` runs, plus CPU time.
The brute-force references are per-point Python loops: (a) "loop + KD-tree" (for each point: a
scipy ball query, numpy.linalg.eigh of the neighbourhood, a nearest-neighbour query), the code a
careful person writes first; (b) "exact scan" (each point scans every point, no index). Both are
timed on a random subset of scored points and extrapolated per point to the whole frame (said in
the output); their per-point distances are compared with the fast path's on that subset.
Machine load (os.getloadavg) is printed: timings on a shared machine are upper bounds.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench import metrics as M  # noqa: E402
from capture.camera import Intrinsics  # noqa: E402

K640 = Intrinsics(640, 480, 536.628, 536.606, 310.591, 234.759)
REAL = Path(os.environ.get("DEPTHBENCH_REAL_DATA", Path(__file__).resolve().parents[2] / "shared" / "data" / "real"))


def synthetic_frame(seed: int = 0):
    """A full-frame room at 1-3.2 m: back wall, a slanted floor, a box and a sphere."""
    rng = np.random.default_rng(seed)
    H, W = K640.height, K640.width
    v, u = np.mgrid[0:H, 0:W]
    xn, yn = (u - K640.cx) / K640.fx, (v - K640.cy) / K640.fy
    z = np.full((H, W), 3.2)
    floor = yn > 0.05
    z[floor] = np.minimum(3.2, 1.1 / yn[floor])            # floor plane 1.1 m below the camera
    box = (np.abs(xn + 0.25) < 0.12) & (np.abs(yn - 0.05) < 0.15)
    z[box] = 1.6 + 0.3 * (xn[box] + 0.25)
    d = np.hypot(xn - 0.25, yn + 0.05)
    ball = d < 0.18
    z[ball] = 1.2 - 0.2 * np.sqrt(1 - (d[ball] / 0.18) ** 2)
    truth = z.astype(np.float32)
    ref = (truth + rng.normal(0, 0.001, truth.shape)).astype(np.float32)
    pred = (truth + rng.normal(0, 1.0, truth.shape) * 0.0015 * truth ** 2).astype(np.float32)
    return pred, ref, None


def ddrnet_frame():
    import cv2

    g = REAL / "ddrnet_person" / "group1"
    if not g.is_dir():
        return None
    raw = cv2.imread(str(g / "depth_map" / "frame_000001.png"), cv2.IMREAD_UNCHANGED).astype(np.float32) / 1000
    hq = cv2.imread(str(g / "high_quality_depth" / "frame_000001.png"), cv2.IMREAD_UNCHANGED).astype(np.float32) / 1000
    mask = cv2.imread(str(g / "mask" / "frame_000001.png"), cv2.IMREAD_UNCHANGED) > 0
    raw[raw == 0] = np.nan
    hq[hq == 0] = np.nan
    return raw, hq, mask


def points(depth, valid):
    v, u = np.nonzero(valid)
    z = depth[v, u].astype(np.float64)
    return np.stack([(u - K640.cx) / K640.fx * z, (v - K640.cy) / K640.fy * z, z], axis=1), v * K640.width + u


def brute(pred, ref, roi, sample, *, r=0.005, index=True):
    """Per-point loop over the flat pixel indices ``sample``: returns distances (NaN when excluded) and seconds."""
    roi = np.ones(ref.shape, bool) if roi is None else roi
    R, rflat = points(ref, np.isfinite(ref) & (ref > 0) & roi)
    Q, _ = points(pred, np.isfinite(pred) & (pred > 0) & roi)
    where = {int(f): k for k, f in enumerate(rflat)}
    t0 = time.perf_counter()
    if index:
        rt, qt = cKDTree(R), cKDTree(Q)
    out = np.full(len(sample), np.nan)
    for k, f in enumerate(sample):
        p = R[where[int(f)]]
        if index:
            nb = R[rt.query_ball_point(p, r)]
        else:
            nb = R[np.einsum("ij,ij->i", R - p, R - p) <= r * r]
        if len(nb) < 3:
            continue
        c = nb.mean(axis=0)
        w, vec = np.linalg.eigh((nb - c).T @ (nb - c) / len(nb))
        if not w[1] > 0.01 * w[2]:
            continue
        if index:                      # 8 candidates, exact ties to the lowest pixel index (the metric's rule)
            cand = np.sort(qt.query(p, k=8)[1])
            d = Q[cand] - p
            q = Q[cand[np.argmin(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])]]
        else:
            d = Q - p
            q = Q[np.argmin(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])]
        out[k] = abs(vec[:, 0] @ (q - c))
    return out, time.perf_counter() - t0


def timed(fn, repeats):
    walls, cpus = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        res = fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return res, min(walls), float(np.median(walls)), min(cpus)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--subset", type=int, default=2000, help="points timed by the loop + KD-tree brute force")
    ap.add_argument("--scan-subset", type=int, default=150, help="points timed by the exact-scan brute force")
    args = ap.parse_args(argv)
    print(f"plane-fit RMSE, 640x480, radius 5 mm, {args.threads} thread(s); load average "
          f"{' '.join(f'{x:.1f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs")
    frames = {"synthetic": synthetic_frame()}
    real = ddrnet_frame()
    if real is not None:
        frames["ddrnet"] = real
    else:
        print(f"(ddrnet frame skipped: {REAL / 'ddrnet_person'} not found)")
    ok = True
    for name, (pred, ref, roi) in frames.items():
        M.plane_fit_rmse(pred, ref, K640, roi=roi, threads=args.threads)          # warm caches (rays)
        res, wmin, wmed, cpu = timed(lambda: M.plane_fit_rmse(pred, ref, K640, roi=roi, threads=args.threads),
                                     args.repeats)
        kd, kwmin, kwmed, kcpu = timed(lambda: M.plane_fit_rmse(pred, ref, K640, roi=roi, method="kdtree",
                                                                threads=args.threads), max(3, args.repeats // 5))
        n_scored = int(np.count_nonzero(res.status))
        used = np.flatnonzero(res.status.ravel() >= 1)
        rng = np.random.default_rng(1)
        sample = np.sort(rng.choice(used, size=min(args.subset, used.size), replace=False))
        d_loop, t_loop = brute(pred, ref, roi, sample, index=True)
        scan = sample[:args.scan_subset]
        d_scan, t_scan = brute(pred, ref, roi, scan, index=False)
        fast = res.distance_m.ravel()[sample]
        same_nan = np.array_equal(np.isnan(fast), np.isnan(d_loop)) and \
            np.array_equal(np.isnan(fast[:len(scan)]), np.isnan(d_scan))
        both = np.isfinite(fast) & np.isfinite(d_loop)
        rel = np.max(np.abs(fast[both] - d_loop[both]) / np.maximum(d_loop[both], 1e-9)) if both.any() else 0.0
        rmse_fast = np.sqrt(np.mean(fast[both] ** 2)) * 1000
        rmse_loop = np.sqrt(np.mean(d_loop[both] ** 2)) * 1000
        loop_frame = t_loop / len(sample) * n_scored
        scan_frame = t_scan / len(scan) * n_scored
        print(f"\n[{name}] {n_scored} scored points, {res.n_used} with a plane "
              f"({res.n_excluded_few} too few neighbours, {res.n_excluded_degenerate} line-like); "
              f"plane-fit RMSE {res.rmse_mm:.4f} mm (KD-tree variant {kd.rmse_mm:.4f} mm)")
        print(f"  fast grid:        wall min {wmin * 1e3:7.1f} ms, median {wmed * 1e3:7.1f} ms, CPU {cpu * 1e3:7.1f} ms")
        print(f"  fast KD-tree:     wall min {kwmin * 1e3:7.1f} ms, median {kwmed * 1e3:7.1f} ms, CPU {kcpu * 1e3:7.1f} ms")
        print(f"  brute loop+KD-tree: {t_loop / len(sample) * 1e6:.1f} us/point on {len(sample)} points -> "
              f"{loop_frame:.1f} s per frame (extrapolated)")
        print(f"  brute exact scan:   {t_scan / len(scan) * 1e3:.2f} ms/point on {len(scan)} points -> "
              f"{scan_frame:.0f} s per frame (extrapolated)")
        print(f"  speed-up (wall min): {loop_frame / wmin:.0f}x over loop+KD-tree, {scan_frame / wmin:.0f}x over the scan")
        print(f"  equal results on the subset: exclusions {'identical' if same_nan else 'DIFFER'}, "
              f"max relative distance difference {rel:.2e}, subset RMSE {rmse_fast:.6f} vs {rmse_loop:.6f} mm; "
              f"grid vs KD-tree RMSE relative difference {abs(res.rmse_mm / kd.rmse_mm - 1):.1e}")
        good = same_nan and rel < 1e-6 and abs(res.rmse_mm / kd.rmse_mm - 1) < 1e-9 and loop_frame / wmin >= 50
        if name == "synthetic":
            good = good and wmin <= 0.100
            print(f"  target (full frame <= 100 ms, >= 50x, equal): {'met' if good else 'NOT met'}")
        ok = ok and good
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
