"""The reference at the LQ instant (:mod:`align.motion`) against the plain warp: error against truth, and throughput.

Run:  .venv/bin/python perf/reference_motion.py SESSION [SESSION ...] [--frames 16]

Each SESSION is a simulated lq-hq session (``depthbench capture simulate ... --frame-phase-ms 7``).
``--frames`` LQ frames spread over the session are each paired with the HQ frame nearest to their
instant, as ``align`` pairs them (dejittered host stamps, truth's time shift and ``T_lq_hq``, so
only the reference's own error is left), and both references get ``align``'s edge rule
(``--edges``, :mod:`align.reference_edges`). For each session it prints the time apart of the pairs
and, for the plain warp and the motion-compensated reference, against the LQ truth depth on the
region of interest (computed as ``align`` does): MAE, RMSE, share of pixels off by more than
50 mm; the share of ROI pixels the motion compensation masked (:attr:`align.motion.Compensated.masked`),
and the net share of ROI reference pixels lost against the plain warp (the edge rule's mask moves
with the edges, so this can differ either way). Then the throughput of both, in pairs per second, one thread, frames in memory: the
plain warp (one warp per pair) and the compensated reference (one new warp per pair, the other
HQ frame cached, plus the compensation), and their ratio (issue 12: at least 0.5), by the wall clock
and by the process's CPU time (steadier when other jobs share the machine).
"""
from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import time  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from align.motion import MotionReference  # noqa: E402
from align.pipeline import pair_setup  # noqa: E402
from align.reference_edges import EdgeRule  # noqa: E402
from align.roi import background_depth, foreground_mask  # noqa: E402
from align.warp import DepthWarper  # noqa: E402
from capture.session import open_session  # noqa: E402
from capture.truth import read_truth  # noqa: E402


def _pairs(root: str, n: int, rule: EdgeRule):
    """``(setup, warper, truth, [(hq index, lq index, dt_us)])`` for ``n`` LQ frames spread over the session."""
    sess, tr = open_session(root), read_truth(root)
    setup = pair_setup(sess, lq="lq", hq="hq")
    warper = DepthWarper(setup.K_hq, setup.K_lq, tr.T_lq_hq, edge_reach=rule.edge_reach)
    pairs = []
    for j in np.linspace(2, setup.f_lq.size - 3, n).round().astype(int):
        s = setup.t_lq[j] - tr.time_shift_at_us(setup.t_lq[j])
        i = int(np.argmin(np.abs(setup.t_hq - s)))
        pairs.append((i, int(j), float(s - setup.t_hq[i])))
    return setup, warper, tr, pairs


def _scores(setup, warper, tr, pairs, rule: EdgeRule) -> dict:
    sess = setup.session
    read = {}

    def warped(i):
        read[i] = sess.read_depth("hq", int(setup.f_hq[i]))
        return warper(read[i])

    plain = MotionReference(warped, setup.t_hq, enabled=False)
    moved = MotionReference(warped, setup.t_hq)
    rows, maps = [], []
    for i, j, dt in pairs:
        lq = sess.read_depth("lq", int(setup.f_lq[j]))
        ref, pm = moved(i, dt)
        rows.append((rule.apply(plain(i, dt)[0])[0], rule.apply(ref)[0], tr.depth("lq", int(setup.f_lq[j])), lq))
        maps.append(pm.masked_map)
    bg = background_depth(np.stack([np.where(np.isfinite(p), p, lq) for p, _, _, lq in rows]))
    out = {}
    for name, col in (("plain", 0), ("compensated", 1)):
        err, n_roi, n_masked, n_lost = [], 0, 0, 0
        for row, masked in zip(rows, maps):
            p, ref, truth, lq = row[0], row[col], row[2], row[3]
            roi = foreground_mask(np.where(np.isfinite(p), p, lq), bg) & np.isfinite(truth)
            n_roi += int((roi & np.isfinite(p)).sum())
            n_masked += 0 if masked is None else int((roi & masked).sum())
            n_lost += int((roi & np.isfinite(p)).sum() - (roi & np.isfinite(ref)).sum())
            err.append((ref - truth)[roi & np.isfinite(ref)])
        e = np.abs(np.concatenate(err)) * 1000
        out[name] = (e.mean(), np.sqrt(np.mean(e ** 2)), 100 * np.mean(e > 50), 100 * n_masked / max(n_roi, 1),
                     100 * n_lost / max(n_roi, 1))
    return out


def _throughput(setup, warper, frames: int) -> tuple[tuple[float, float], tuple[float, float]]:
    """Pairs per second of the plain warp and of the compensated reference over ``frames`` consecutive
    pairs: ``((plain, compensated) by the wall clock, (plain, compensated) by this process's CPU time)``.
    The CPU time is the steadier on a shared machine (other jobs take the wall clock, not it); each is
    the best of three rounds, plain and compensated taking turns."""
    sess = setup.session
    n = min(frames, setup.f_hq.size - 1)
    depth = [sess.read_depth("hq", int(setup.f_hq[i])) for i in range(n + 1)]
    dt = 0.25 * float(np.median(np.diff(setup.t_hq)))  # a quarter period apart: every pair compensated
    for enabled in (False, True):
        MotionReference(lambda i: warper(depth[i]), setup.t_hq, enabled=enabled)(0, dt)  # warm-up (numba compile)
    wall, cpu = {False: [], True: []}, {False: [], True: []}
    for _ in range(3):
        for enabled in (False, True):
            ref = MotionReference(lambda i: warper(depth[i]), setup.t_hq, enabled=enabled)
            t0, c0 = time.perf_counter(), time.process_time()
            for i in range(n):
                ref(i, dt)
            wall[enabled].append(n / (time.perf_counter() - t0))
            cpu[enabled].append(n / (time.process_time() - c0))
    return (max(wall[False]), max(wall[True])), (max(cpu[False]), max(cpu[True]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sessions", nargs="+", help="simulated lq-hq sessions (with truth/)")
    ap.add_argument("--frames", type=int, default=16, help="LQ frames per session (default: %(default)s)")
    ap.add_argument("--speed-frames", type=int, default=40, help="pairs for the throughput (default: %(default)s)")
    ap.add_argument("--edges", choices=("strict", "midpoint"), default="strict",
                    help="the reference's edge rule, align.reference_edges (default: %(default)s, as align)")
    args = ap.parse_args()
    cv2.setNumThreads(1)
    print("| session | time apart (ms) | plain MAE / RMSE / >50 mm | compensated MAE / RMSE / >50 mm | masked by the "
          "motion | net reference pixels lost |")
    print("|---|---|---|---|---|---|")
    for root in args.sessions:
        rule = EdgeRule.named(args.edges)
        setup, warper, tr, pairs = _pairs(root, args.frames, rule)
        s = _scores(setup, warper, tr, pairs, rule)
        dts = np.array([abs(p[2]) for p in pairs]) / 1000
        (pm, pr, pb, _, _), (cm, cr, cb, masked, lost) = s["plain"], s["compensated"]
        print(f"| {root} | {dts.min():.1f}-{dts.max():.1f} | {pm:.1f} / {pr:.1f} mm / {pb:.2f} % | "
              f"{cm:.1f} / {cr:.1f} mm / {cb:.2f} % | {masked:.2f} % | {lost:.2f} % |", flush=True)
    if args.speed_frames > 0:
        (plain, moved), (plain_cpu, moved_cpu) = _throughput(setup, warper, args.speed_frames)
        print(f"\nthroughput ({args.sessions[-1]}, {args.speed_frames} consecutive pairs, one thread, best of 3): "
              f"plain warp {plain:.1f} pairs/s, compensated {moved:.1f} pairs/s, ratio {moved / plain:.2f} "
              f"(wall clock); "
              f"{plain_cpu:.1f} / {moved_cpu:.1f} pairs/s, ratio {moved_cpu / plain_cpu:.2f} (CPU time)")

if __name__ == "__main__":
    main()
