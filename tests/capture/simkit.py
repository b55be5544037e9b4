"""Small simulated sessions shared by the simulator tests (made once per test run, in a
temporary folder removed at exit)."""
from __future__ import annotations

import atexit
import shutil
import tempfile
from functools import lru_cache
from pathlib import Path

import numpy as np

from capture.session import open_session
from capture.sim import simulate
from capture.truth import read_truth

_ROOT = Path(tempfile.mkdtemp(prefix="depthbench-simtests-"))
atexit.register(shutil.rmtree, _ROOT, ignore_errors=True)

#: name -> simulate() keyword arguments
SESSIONS = {
    # static textured panels at 1.0 .. 3.0 m: depth bands for the noise model
    "planes": dict(rig="lq-hq", scene="planes", seconds=0.2, seed=5, static=True, scale=0.5),
    # moving people, declared clock drift and drops
    "people_declared": dict(rig="lq-hq", scene="people", seconds=0.5, seed=3, scale=0.25,
                            effects={"clock_drift_ppm": 400.0, "frame_drop_rate": 0.25}),
    "people_undeclared": dict(rig="lq-hq", scene="people", seconds=0.5, seed=3, scale=0.25, undeclared=True,
                              effects={"clock_drift_ppm": 400.0, "frame_drop_rate": 0.25}),
    # depth scale and lens distortion on the LQ camera, declared and not
    "lens_declared": dict(rig="lq-hq", scene="planes", seconds=0.07, seed=2, static=True, scale=0.5,
                          effects={"depth_scale": 1.1, "distortion_k1": -0.2}),
    "lens_undeclared": dict(rig="lq-hq", scene="planes", seconds=0.07, seed=2, static=True, scale=0.5,
                            undeclared=True, effects={"depth_scale": 1.1, "distortion_k1": -0.2}),
    "multiview": dict(rig="multiview4-hq", scene="balloons", seconds=0.1, seed=4, scale=0.25),
}


@lru_cache(maxsize=None)
def session(name: str) -> Path:
    """The folder of simulated session ``name`` (see :data:`SESSIONS`), simulated on first use."""
    out = _ROOT / name
    simulate(out, progress=False, workers=1, **SESSIONS[name])
    return out


def pairs(name: str, sensor: str):
    """Yield ``(frame_number, measured depth, truth depth)`` (float32 metres, NaN = none)."""
    root = session(name)
    s, t = open_session(root), read_truth(root)
    for fn in s.frames(sensor, "depth")["frame_number"]:
        yield int(fn), s.read_depth(sensor, int(fn)), t.depth(sensor, int(fn))


def robust_std(x: np.ndarray) -> float:
    """1.4826 * median absolute deviation: the standard deviation of the Gaussian part."""
    x = np.asarray(x, dtype=np.float64)
    return float(1.4826 * np.median(np.abs(x - np.median(x))))
