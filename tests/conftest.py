"""Shared fixtures: the real-data folder (skips with a reason when absent) and a CLI runner."""
from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
REAL_DATA = Path(os.environ.get("DEPTHBENCH_REAL_DATA", REPO.parent / "shared" / "data" / "real"))
ARTIFACTS = Path(os.environ.get("DEPTHBENCH_TEST_ARTIFACTS", REPO / "test-artifacts"))


@pytest.fixture(scope="session")
def real_data() -> Path:
    """``../shared/data/real``; the test is skipped when it is absent (a clone without shared/)."""
    if not REAL_DATA.is_dir():
        pytest.skip(f"real sensor data not found at {REAL_DATA} (set DEPTHBENCH_REAL_DATA or place shared/ beside the repo)")
    return REAL_DATA


@pytest.fixture(scope="session")
def artifacts() -> Path:
    """Folder for files a person may want to look at after the run (screenshots, plots)."""
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    return ARTIFACTS


@dataclass
class CliResult:
    returncode: int
    stdout: str
    stderr: str


@pytest.fixture
def cli():
    """Run ``depthbench ARGS...`` in a subprocess, as a user would; returns a :class:`CliResult`."""

    def run(*args: str, timeout: float = 600, cwd: str | os.PathLike | None = None) -> CliResult:
        proc = subprocess.run([sys.executable, "-m", "depthbench", *map(str, args)], capture_output=True, text=True,
                              timeout=timeout, cwd=cwd)
        return CliResult(proc.returncode, proc.stdout, proc.stderr)

    return run


def assert_one_line_error(result: CliResult, *fragments: str) -> None:
    """A user error: exit status 2, no traceback, one line on stderr naming ``fragments``."""
    assert result.returncode == 2, (result.returncode, result.stderr)
    assert "Traceback" not in result.stderr, result.stderr
    lines = [line for line in result.stderr.strip().splitlines() if line.strip() and "[depthai]" not in line]
    assert len(lines) == 1, result.stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
