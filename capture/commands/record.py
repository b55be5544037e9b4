"""``depthbench capture record --rig RIG.toml --out DIR [--seconds S]``: record every sensor of a rig."""
from __future__ import annotations

import signal
import sys

from capture.recorder import default_writers, record
from capture.rig import load_rig


def add_parser(sub) -> None:
    p = sub.add_parser(
        "record", help="record every sensor of a rig file into a crash-safe session folder",
        description="Open every sensor of the rig file (data_manifests/rig.md), record them at once into a session "
                    "folder (data_manifests/session.md) and show per-stream frame rate and drops on stderr. Each "
                    "frame is on disk before it is indexed, so a crash leaves a readable session "
                    "('depthbench capture repair' tidies it). Dropped and duplicated frames are counted per stream "
                    "and written to session.json. Ctrl-C (or SIGTERM) stops cleanly.",
        epilog="Example: depthbench capture record --rig data_manifests/rigs/replay-lq-hq.toml --out rec1 --seconds 10")
    p.add_argument("--rig", required=True, metavar="RIG.toml", help="rig file naming the sensors, drivers and streams")
    p.add_argument("--out", required=True, metavar="DIR", help="session folder to create")
    p.add_argument("--seconds", type=float, default=None, metavar="S",
                   help="stop after S seconds (default: until every source ends, or Ctrl-C)")
    p.add_argument("--force", action="store_true", help="replace DIR if it exists")
    p.add_argument("--writers", type=int, default=None, metavar="N",
                   help=f"PNG encoder threads (default: one per core plus one, at least 3; here {default_writers()})")
    p.add_argument("--buffer", type=float, default=1.0, metavar="S",
                   help="seconds of frames the write queue holds before frames are dropped as writer drops (default 1)")
    p.add_argument("--no-adaptive", action="store_true",
                   help="always compress PNGs (default: write them uncompressed while the writer is falling behind)")
    p.add_argument("--fsync", action="store_true", help="fsync every frame and index row (survives power loss; slower)")
    p.add_argument("--no-space-check", action="store_true",
                   help="record even when --seconds of uncompressed frames would not fit the free disk space "
                        "(checked by default)")
    p.add_argument("--quiet", action="store_true", help="no live progress line")
    p.set_defaults(func=run)


def _sigterm(signum, frame):  # stop like Ctrl-C: finish the session cleanly
    raise KeyboardInterrupt


def run(args) -> int:
    rig = load_rig(args.rig)
    previous = signal.signal(signal.SIGTERM, _sigterm)
    try:
        result = record(rig, args.out, seconds=args.seconds, force=args.force, writers=args.writers,
                        buffer_s=args.buffer, fsync=args.fsync, progress=None if args.quiet else sys.stderr,
                        progress_every_s=1.0 if sys.stderr.isatty() else 5.0, adaptive=not args.no_adaptive,
                        check_space=not args.no_space_check)
    finally:
        signal.signal(signal.SIGTERM, previous)
    print(result.message)
    return 0
