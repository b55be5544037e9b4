"""The ``depthbench`` console command: one subcommand per stage.

Each stage package owns a ``cli`` module with ``register(subparsers)``; this module only
collects them, so adding a stage never touches another stage's code.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import sys

from depthbench.errors import DepthbenchError

#: (subcommand, module that registers it); order is the order shown in ``--help``.
STAGES = (
    ("capture", "capture.cli"),
    ("align", "align.cli"),
    ("methods", "methods.cli"),
    ("bench", "bench.cli"),
    ("demo", "depthbench.demo"),
)


class _Parser(argparse.ArgumentParser):
    """argparse that reports usage errors as one line and exit status 2."""

    def error(self, message: str) -> None:  # pragma: no cover - exercised via CLI tests
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="depthbench",
        description=(
            "Record RGB-D streams from a noisy LQ depth sensor next to an HQ reference, align them "
            "in time and space, run depth-denoising methods and score them."
        ),
        epilog="Run 'depthbench STAGE --help' for each stage. Errors exit with status 2.",
    )
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    sub = parser.add_subparsers(dest="stage", metavar="STAGE", parser_class=_Parser)
    sub.required = True
    for name, module_name in STAGES:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:  # a stage not built yet must not break the others
            if exc.name != module_name:
                raise
            continue
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose + 1, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    try:
        return int(args.func(args) or 0)
    except DepthbenchError as exc:
        message = str(exc)
        if exc.cli_hint and exc.cli_hint not in message:
            message = f"{message}; {exc.cli_hint}"
        print(f"depthbench {args.stage}: error: {message}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print(f"depthbench {args.stage}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
