"""``run_diagnose``: load a capture, diagnose it, optionally its simulated twin, write the report."""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from bench.diagnose.core import DiagnoseResult, diagnose
from bench.diagnose.sources import load


@dataclass
class DiagnoseRun:
    """What :func:`run_diagnose` produced: the diagnosis, the sim-to-real tables, the report folder."""

    result: DiagnoseResult
    sim_to_real: dict | None
    report: Path


def run_diagnose(data: str | os.PathLike, out: str | os.PathLike, *, force: bool = False, max_frames: int = 60,
                 sim_to_real: bool = False, seed: int = 0) -> DiagnoseRun:
    """Diagnose ``data`` (see :func:`bench.diagnose.sources.load`) and write the report to ``out``."""
    from bench.diagnose.report import write_report
    from depthbench.fsutil import check_output_free

    check_output_free(Path(out), force=force, what="diagnosis report")
    frames = load(data, max_frames=max_frames)
    result = diagnose(frames, source=str(data))
    s2r = None
    if sim_to_real:
        from bench.diagnose.twin import sim_to_real_tables

        s2r = sim_to_real_tables(frames, result, seed=seed)
    return DiagnoseRun(result, s2r, write_report(result, out, force=force, sim_to_real=s2r))
