"""Run ``depthbench`` in this process (fast), capturing stdout/stderr at the file-descriptor level.

Subprocess runs (the ``cli`` fixture) cost a few seconds of start-up each; tests that check many
bad inputs use this instead and keep one subprocess run per command for the real thing. ``capfd``
also catches what C libraries (libpng, librealsense, FFmpeg) print, so the one-line check is as
strict as with a subprocess.
"""
from __future__ import annotations

from tests.conftest import CliResult


def run_inproc(capfd, *args) -> CliResult:
    from depthbench.cli import main

    capfd.readouterr()
    try:
        code = main([str(a) for a in args])
    except SystemExit as exc:  # argparse usage errors
        code = int(exc.code or 0)
    out, err = capfd.readouterr()
    return CliResult(code, out, err)
