"""``depthbench capture validate SESSION``: check a session folder against the format."""
from __future__ import annotations

from capture.session import open_session


def add_parser(sub) -> None:
    p = sub.add_parser("validate", help="check a session folder (manifest, frame tables, every frame)",
                       description="Check session.json against the schema, every frames.csv, and (unless --quick) "
                                   "decode every frame and compare its checksum, size and bit depth.")
    p.add_argument("session", help="session folder")
    p.add_argument("--quick", action="store_true", help="check the manifest and frame tables only, not every frame")
    p.set_defaults(func=run)


def run(args) -> int:
    session = open_session(args.session, verify="index" if args.quick else "full")
    n = sum(len(session.frames(s)) for s in session.sensors)
    print(f"{args.session}: valid session '{session.name}' ({len(session.sensors)} sensors, {n} frames"
          f"{', frames not decoded' if args.quick else ', every frame checked'})")
    return 0
