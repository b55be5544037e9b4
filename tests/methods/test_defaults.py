"""The defaults are the sweep's winners, stored with the methods and justified by its table."""
import json
from pathlib import Path

from methods import get
from methods._defaults import DEFAULTS_PATH

TABLE = Path(__file__).resolve().parents[2] / "methods" / "defaults_sweep.md"


def test_methods_use_the_swept_defaults_and_the_table_shows_them():
    stored = json.loads(DEFAULTS_PATH.read_text())
    table = TABLE.read_text()
    assert "Held-out frames" in table and "sweep_defaults" in stored["_comment"]
    for name in ("gaussian", "bilateral", "joint_bilateral", "rolling_guidance"):
        params = get(name).params
        for k, v in stored[name].items():
            assert params[k] == (float("inf") if v == "inf" else v), (name, k)
        row = f"| {name} | {', '.join(f'{k}={v}' for k, v in stored[name].items())} |"
        assert row in table, row
