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
