"""Simulated sessions shared by the alignment tests (small: half resolution, two seconds)."""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest


def simulate_session(root: Path, **kw) -> Path:
    from capture.sim import simulate

    args = dict(rig="lq-hq", scene="people", seconds=2.0, seed=11, scale=0.5, progress=False)
    args.update(kw)
    simulate(root, **args)
    return root


@pytest.fixture(scope="session")
def sim_plus55(tmp_path_factory) -> Path:
    """lq-hq, people walking, true shift +55 ms."""
    return simulate_session(tmp_path_factory.mktemp("sim") / "plus55", time_shift_us=55_000, seed=11)


@pytest.fixture(scope="session")
def sim_static(tmp_path_factory) -> Path:
    """lq-hq, nothing moves: the shift is unobservable."""
    return simulate_session(tmp_path_factory.mktemp("sim") / "static", time_shift_us=-20_000, seed=12, static=True,
                            seconds=1.5)


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def refresh_checksums(root: Path) -> None:
    """After editing a frames table by hand: put its new sha256 into session.json."""
    m = json.loads((root / "session.json").read_text())
    for sid, s in m["sensors"].items():
        m.setdefault("checksums", {})[s["frames"]] = _sha(root / s["frames"])
    (root / "session.json").write_text(json.dumps(m, indent=2))
