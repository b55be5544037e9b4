"""Time-shift search throughput and accuracy on a 30 s lq-hq session (two cores).

Run:  .venv/bin/python perf/align_shift.py [--session SIM] [--workers 2] [--probes 24]

Without ``--session`` it first simulates a 30 s lq-hq session (default resolutions; minutes, ~2 GB) into
``--cache`` (a temporary folder by default) and reuses it on later runs. It then runs the fit that ``depthbench align`` runs
(:func:`align.pipeline.fit_pair`: probe features once per frame, the coarse scan over +-60 ms,
the bracketing refinement, T_ex), timed, and prints:

* wall seconds of the whole search, split into feature work (reading frames, SIFT, matching,
  KLT tracks; ``--workers`` threads) and the search itself (loss evaluations, PnP, refinement);
* how many loss evaluations the search made, and what recomputing the features for every
  candidate would have cost instead (evaluations x feature time);
* the errors against ``truth/`` (Delta in microseconds, T_lq_hq in mm and degrees);
* the machine's load average (the suite is developed on a shared machine).
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from align.pipeline import AlignOptions, build_probes, fit_pair, pair_setup
from capture.session import open_session


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--session", help="simulated lq-hq session (default: simulate 30 s into --cache)")
    ap.add_argument("--cache", default=str(Path(tempfile.gettempdir()) / "depthbench-align-shift-lqhq30"),
                    help="where the simulated session (about 2 GB) is kept between runs (default: %(default)s)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--probes", type=int, default=24)
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args()
    root = Path(args.session or args.cache)
    if not (root / "session.json").is_file():
        from capture.sim import simulate

        print(f"simulating a 30 s lq-hq session into {root} (once) ...", flush=True)
        simulate(root, rig="lq-hq", scene="people", seconds=30.0, seed=args.seed, progress=True)
    sess = open_session(root)
    print(f"session {root}: {sess.timestamps_us('hq').size} HQ and {sess.timestamps_us('lq').size} LQ frames; "
          f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    opts = AlignOptions(workers=args.workers, probes=args.probes, progress=False)
    setup = pair_setup(sess, lq="lq", hq="hq")
    t0 = time.perf_counter()
    probes, _ = build_probes(setup, opts)
    t_feat = time.perf_counter() - t0
    t0 = time.perf_counter()
    pf = fit_pair(setup, opts)  # the whole fit again, features included: the number that counts
    t_all = time.perf_counter() - t0
    sh = pf.shift
    per_probe = t_feat / max(len(probes), 1)
    print(f"full Delta search over +-{opts.shift_range_ms:g} ms ({len(pf.probes)} probe frames, {args.workers} workers): "
          f"{t_all:.2f} s wall")
    print(f"  feature work (once per frame): {t_feat:.2f} s; search + T_ex: {t_all - t_feat:.2f} s; "
          f"{sh.evaluations} loss evaluations")
    print(f"  recomputing features per candidate instead: ~{sh.evaluations * per_probe * len(probes):.0f} s")
    try:
        from capture.truth import read_truth

        tr = read_truth(root)
        dt, dr = pf.T_lq_hq.error_to(tr.T_lq_hq)
        print(f"  Delta = {sh.time_shift_us:.0f} us (+- {sh.std_us:.0f}), truth {tr.time_shift_us} us: error "
              f"{sh.time_shift_us - tr.time_shift_us:+.0f} us; T_lq_hq error {1e3 * dt:.2f} mm, {dr:.4f} deg")
    except Exception as exc:  # a real session has no truth
        print(f"  Delta = {sh.time_shift_us:.0f} us (+- {sh.std_us:.0f}); no truth ({exc})")


if __name__ == "__main__":
    main()
