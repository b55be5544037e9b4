"""``depthbench capture ...``: one module per sub-command under ``capture/commands/``.

Each command module defines ``add_parser(subparsers)`` that registers its parser and sets
``func``. A module that does not exist yet is skipped, so commands land independently.
"""
from __future__ import annotations

import importlib

COMMANDS = (
    "simulate",     # capture/commands/simulate.py   - simulated rigs with ground truth
    "devices",      # capture/commands/devices.py    - list connected sensors
    "record",       # capture/commands/record.py     - record a rig file
    "import",       # capture/commands/import_.py    - realsense .db3, azure-kinect .mkv, tum folders
    "repair",       # capture/commands/repair.py     - tidy a session a crash left inconsistent
    "validate",     # capture/commands/validate.py   - check a session folder
    "info",         # capture/commands/info.py       - summarise a session folder
)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "capture", help="record, import, simulate and check RGB-D sessions",
        description="Record sensors, import recordings, simulate rigs with ground truth, and check session folders.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=type(parser))
    sub.required = True
    for name in COMMANDS:
        module_name = f"capture.commands.{'import_' if name == 'import' else name}"
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name != module_name:
                raise
            continue
        module.add_parser(sub)
