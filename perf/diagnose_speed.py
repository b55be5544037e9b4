"""Speed of ``bench diagnose`` on one simulated 30 s ``lq-hq`` session (issue 13: under a minute
on two cores).

Run:  .venv/bin/python perf/diagnose_speed.py [--seconds 30] [--max-frames 60]

Simulates the session into a temporary folder (the simulator's truth is the reference), then
times, in the same run, the reference -- reading the frames the diagnosis uses (``load``) --
and the whole diagnosis (``load`` + :func:`bench.diagnose.diagnose` of both sensors), and prints
seconds and their ratio. The machine may be shared: the load average is printed too.

The diagnosis reads at most ``--max-frames`` evenly spaced frames per sensor (60 at 30 fps is
2 s), so ``--seconds 2`` times the same diagnosis work as a 30 s session with less simulating.
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=30.0, help="scene time of the session (default 30)")
    ap.add_argument("--max-frames", type=int, default=60, help="frames per sensor the diagnosis reads (default 60)")
    args = ap.parse_args()
    from bench.diagnose import diagnose
    from bench.diagnose.sources import load
    from capture.sim import simulate

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "session"
        t0 = time.perf_counter()
        simulate(root, rig="lq-hq", scene="people", seconds=args.seconds, seed=3, progress=False)
        print(f"simulated {args.seconds:g} s of lq-hq in {time.perf_counter() - t0:.1f} s "
              f"(cores: {os.cpu_count()}, load average: {os.getloadavg()[0]:.1f})")
        t0 = time.perf_counter()
        frames = load(root, max_frames=args.max_frames)
        t_load = time.perf_counter() - t0
        t0 = time.perf_counter()
        res = diagnose(frames, source=str(root))
        t_diag = time.perf_counter() - t0
    total = t_load + t_diag
    print(f"reading {sum(len(f.depth) for f in frames)} frames (+ truth): {t_load:.1f} s")
    print(f"diagnosis of {len(res.sensors)} sensors: {t_diag:.1f} s; load + diagnosis: {total:.1f} s "
          f"({total / t_load:.1f}x reading; target < 60 s: {'yes' if total < 60 else 'NO'})")
    for name, d in res.sensors.items():
        print(f"  {name}: sigma model {d.sigma_models.chosen}, {d.derived.get('subpixel_px', float('nan')):.4f} px, "
              f"correlation {d.derived.get('correlation_px') or 0:.2f} px, fill {d.fill_rate:.3f}")


if __name__ == "__main__":
    main()
