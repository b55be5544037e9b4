"""``depthbench capture repair SESSION``: tidy a session folder a crash left inconsistent."""
from __future__ import annotations

from capture.repair import repair


def add_parser(sub) -> None:
    p = sub.add_parser(
        "repair", help="rebuild a session a crash left inconsistent (partial rows, unindexed frames, checksums)",
        description="Truncate a partial last line of each frames.csv, remove index rows whose frame is missing or "
                    "does not match its checksum, delete temporary and unindexed frame files, recompute the "
                    "frames-table checksums and dropped-frame counts, and mark the session 'repaired'. A session "
                    "that needs none of this is left untouched. The result is checked by reading every frame.")
    p.add_argument("session", help="session folder")
    p.add_argument("--dry-run", action="store_true", help="report what would be done, change nothing")
    p.add_argument("-v", "--verbose", action="store_true", help="list every removed row and file")
    p.set_defaults(func=run)


def run(args) -> int:
    result = repair(args.session, dry_run=args.dry_run)
    if args.verbose or args.dry_run:
        for line in result.rows_removed:
            print(f"  remove row  {line}")
        for f in result.files_removed:
            print(f"  delete file {f}")
    print(("(dry run) " if args.dry_run and result.changed else "") + result.summary())
    return 0
