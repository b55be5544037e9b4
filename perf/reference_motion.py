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
from align.motion_flow import FlowMotion, SceneFlow  # noqa: E402
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
    flow = MotionReference(warped, setup.t_hq, moved=_flow_motion(setup, warper, lambda i: sess.read_depth("hq", int(setup.f_hq[i]))))
    rows, maps = [], []
    for i, j, dt in pairs:
        lq = sess.read_depth("lq", int(setup.f_lq[j]))
        ref, pm = moved(i, dt)
        rows.append((rule.apply(plain(i, dt)[0])[0], rule.apply(ref)[0], tr.depth("lq", int(setup.f_lq[j])), lq,
                     rule.apply(flow(i, dt)[0])[0]))
        maps.append(pm.masked_map)
    bg = background_depth(np.stack([np.where(np.isfinite(r[0]), r[0], r[3]) for r in rows]))
    out = {}
    for name, col in (("plain", 0), ("compensated", 1), ("flow", 4)):
        err, n_roi, n_masked, n_lost = [], 0, 0, 0
        for row, masked in zip(rows, maps):
            p, ref, truth, lq = row[0], row[col], row[2], row[3]
            masked = masked if col == 1 else None
            roi = foreground_mask(np.where(np.isfinite(p), p, lq), bg) & np.isfinite(truth)
            n_roi += int((roi & np.isfinite(p)).sum())
            n_masked += 0 if masked is None else int((roi & masked).sum())
            n_lost += int((roi & np.isfinite(p)).sum() - (roi & np.isfinite(ref)).sum())
            err.append((ref - truth)[roi & np.isfinite(ref)])
        e = np.abs(np.concatenate(err)) * 1000
        out[name] = (e.mean(), np.sqrt(np.mean(e ** 2)), 100 * np.mean(e > 50), 100 * n_masked / max(n_roi, 1),
                     100 * n_lost / max(n_roi, 1))
    return out


#: the ROI's background is the depth of the far surfaces over the scored pairs' frames, found where at least this
#: many have depth (:func:`align.roi.background_depth`'s ``min_count``): with fewer pairs there is no ROI to score
MIN_SCORED_FRAMES = 3

FLOW_OPTIONS: dict = {}  # SceneFlow's keyword options (``--flow-stride``)


def _flow_motion(setup, warper, read_depth, read_color=None) -> FlowMotion:
    """:class:`align.motion_flow.FlowMotion` of the session's HQ rig (``read_color`` None: from the session)."""
    sess = setup.session

    def from_session(i):
        c = int(setup.hq_color_of_depth[i])
        return None if c < 0 else sess.read_color(setup.hq, int(setup.f_hq_c[c]))

    return FlowMotion(read_depth, read_color or from_session, warper,
                      SceneFlow(setup.K_hq, setup.K_hq_color, setup.T_hqdepth_hqcolor.inverse(), **FLOW_OPTIONS))


def _throughput(setup, warper, frames: int) -> tuple[tuple[float, float], tuple[float, float]]:
    """Pairs per second of the plain warp and of the compensated reference over ``frames`` consecutive
    pairs: ``((plain, compensated) by the wall clock, (plain, compensated) by this process's CPU time)``.
    The CPU time is the steadier on a shared machine (other jobs take the wall clock, not it); each is
    the best of three rounds, plain and compensated taking turns."""
    sess = setup.session
    n = min(frames, setup.f_hq.size - 1)
    depth = [sess.read_depth("hq", int(setup.f_hq[i])) for i in range(n + 1)]
    color = [sess.read_color(setup.hq, int(setup.f_hq_c[setup.hq_color_of_depth[i]])) for i in range(n + 1)]
    dt = 0.25 * float(np.median(np.diff(setup.t_hq)))  # a quarter period apart: every pair compensated

    def reference(kind):
        moved = None
        if kind == "flow":
            moved = _flow_motion(setup, warper, lambda i: depth[i], lambda i: color[i])  # frames in memory
        return MotionReference(lambda i: warper(depth[i]), setup.t_hq, enabled=kind != "plain", moved=moved)

    kinds = ("plain", "edges", "flow")
    for k in kinds:
        reference(k)(0, dt)  # warm-up (numba compile)
    wall, cpu = {k: [] for k in kinds}, {k: [] for k in kinds}
    for _ in range(3):
        for k in kinds:
            ref = reference(k)
            t0, c0 = time.perf_counter(), time.process_time()
            for i in range(n):
                ref(i, dt)
            wall[k].append(n / (time.perf_counter() - t0))
            cpu[k].append(n / (time.process_time() - c0))
    return {k: max(v) for k, v in wall.items()}, {k: max(v) for k, v in cpu.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sessions", nargs="+", help="simulated lq-hq sessions (with truth/)")
    ap.add_argument("--frames", type=int, default=16,
                    help=f"LQ frames per session (default: %(default)s; under {MIN_SCORED_FRAMES}: throughput only)")
    ap.add_argument("--speed-frames", type=int, default=40, help="pairs for the throughput (default: %(default)s)")
    ap.add_argument("--edges", choices=("strict", "midpoint"), default="strict",
                    help="the reference's edge rule, align.reference_edges (default: %(default)s; align's default, "
                         "footprint-fg, needs align's own references: docs/worklog/2026-11-24-s12/recheck.md scores it)")
    ap.add_argument("--flow-stride", type=int, default=None,
                    help="scene flow found for every N-th HQ sample (align.motion_flow.SceneFlow; default: its own)")
    args = ap.parse_args()
    if args.frames < 0 or args.speed_frames < 0:
        ap.error(f"--frames and --speed-frames must be >= 0, got {args.frames} and {args.speed_frames}")
    if args.flow_stride is not None:
        FLOW_OPTIONS["stride"] = args.flow_stride
    cv2.setNumThreads(1)
    scored = args.frames >= MIN_SCORED_FRAMES
    if scored:
        print("| session | time apart (ms) | plain MAE / RMSE / >50 mm | compensated (edges) MAE / RMSE / >50 mm | "
              "masked by the motion | net reference pixels lost | scene flow MAE / RMSE / >50 mm | net lost (flow) |")
        print("|---|---|---|---|---|---|---|---|")
    else:
        print(f"accuracy not scored: the region of interest's background needs --frames >= {MIN_SCORED_FRAMES} "
              f"(align.roi.background_depth), got {args.frames}")
    for root in args.sessions:
        rule = EdgeRule.named(args.edges)
        setup, warper, tr, pairs = _pairs(root, max(args.frames, 1), rule)
        if not scored:
            continue
        s = _scores(setup, warper, tr, pairs, rule)
        dts = np.array([abs(p[2]) for p in pairs]) / 1000
        (pm, pr, pb, _, _), (cm, cr, cb, masked, lost), (fm, fr, fb, _, flost) = s["plain"], s["compensated"], s["flow"]
        print(f"| {root} | {dts.min():.1f}-{dts.max():.1f} | {pm:.1f} / {pr:.1f} mm / {pb:.2f} % | "
              f"{cm:.1f} / {cr:.1f} mm / {cb:.2f} % | {masked:.2f} % | {lost:.2f} % | "
              f"{fm:.1f} / {fr:.1f} mm / {fb:.2f} % | {flost:.2f} % |", flush=True)
    if args.speed_frames > 0:
        wall, cpu = _throughput(setup, warper, args.speed_frames)
        print(f"\nthroughput ({args.sessions[-1]}, {args.speed_frames} consecutive pairs, one thread, best of 3, "
              f"pairs/s; ratio to the plain warp):")
        for k in ("edges", "flow"):
            print(f"  {k:5s}: wall clock plain {wall['plain']:.1f}, {k} {wall[k]:.1f}, ratio {wall[k] / wall['plain']:.2f}; "
                  f"CPU time plain {cpu['plain']:.1f}, {k} {cpu[k]:.1f}, ratio {cpu[k] / cpu['plain']:.2f}")

if __name__ == "__main__":
    main()
