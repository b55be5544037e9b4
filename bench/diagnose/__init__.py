"""``depthbench bench diagnose``: the measured error model of depth sensors, and the simulator's
distance to it.

* :mod:`bench.diagnose.stats` -- statistics of a depth image against a reference (pure);
* :mod:`bench.diagnose.models` -- candidate error models, fits, selection (pure);
* :mod:`bench.diagnose.core` -- :func:`diagnose` (pure), the result object;
* :mod:`bench.diagnose.twin` -- the simulated twin of a capture and the sim-to-real distance (pure);
* :mod:`bench.diagnose.sources` -- reading sessions, aligned datasets and real captures (I/O);
* :mod:`bench.diagnose.report` -- Markdown report and figures (I/O).
"""
from bench.diagnose.core import DiagnoseResult, SensorDiagnosis, diagnose
from bench.diagnose.data import SensorFrames

__all__ = ["DiagnoseResult", "SensorDiagnosis", "SensorFrames", "diagnose"]
