"""The swept default parameters of the classical filters (``methods/defaults.json``).

The values are chosen by ``methods/tools/sweep_defaults.py`` on simulated people at 1-3 m; the
table that justifies them is ``methods/defaults_sweep.md``.
"""
from __future__ import annotations

import json
import math
from functools import lru_cache
from pathlib import Path

DEFAULTS_PATH = Path(__file__).with_name("defaults.json")


@lru_cache(maxsize=None)
def _all() -> dict:
    return json.loads(DEFAULTS_PATH.read_text())


def swept(method: str) -> dict:
    """The swept defaults of ``method`` (a copy; the string ``"inf"`` is read as ``math.inf``)."""
    return {k: (math.inf if v == "inf" else v) for k, v in _all()[method].items()}


#: Help text of the parameters several filters share (shown by ``depthbench methods list``).
SHARED_HELP = {
    "radius": "window: disk of this radius in pixels; none = ceil(2 * sigma_spatial)",
    "depth_adaptive": "true: sigma_color grows as (z / z_ref)^2 (stereo noise)",
    "z_ref": "depth in metres where sigma_color applies when depth_adaptive",
}


def shared_help(*names: str) -> dict[str, str]:
    """``{name: help}`` of the shared parameters ``names``, in that order (for a filter's ``param_help``)."""
    return {n: SHARED_HELP[n] for n in names}
