"""Compare two ``depthbench demo --out`` folders made from the same seed (e.g. before and after a refactor).

    python scripts/compare_demo_outputs.py BEFORE AFTER

Checks, and prints one line each:

* ``results/results.parquet``: the same columns with the same types, the same rows in the same
  order, the same values (NaN equal to NaN); and whether the files are byte-identical.
* ``aligned/aligned.json``: the same keys and values everywhere, after replacing the BEFORE folder
  by AFTER in paths and leaving out ``alignment.fit_seconds`` (a wall-clock time).
* the frame indexes ``session/*/frames.csv``, ``session/truth/*/frames.csv``, ``aligned/frames.csv``:
  byte-identical, i.e. every frame file has the same sha256.

Exit status 0 when everything is identical, 1 otherwise.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pandas as pd

#: Values that are wall-clock times, not results.
VOLATILE = {("alignment", "fit_seconds")}


def _normalise(obj, before: str, after: str, path=()):
    if isinstance(obj, dict):
        return {k: _normalise(v, before, after, path + (k,)) for k, v in obj.items() if path + (k,) not in VOLATILE}
    if isinstance(obj, list):
        return [_normalise(v, before, after, path) for v in obj]
    if isinstance(obj, str):
        return obj.replace(before, after)
    return obj


def _diff(a, b, path="") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        out = [f"{path}.{k}: only in {'BEFORE' if k in a else 'AFTER'}" for k in sorted(set(a) ^ set(b))]
        for k in a:
            if k in b:
                out += _diff(a[k], b[k], f"{path}.{k}")
        return out
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in _diff(x, y, f"{path}[{i}]")]
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]


def compare_tables(before: Path, after: Path) -> list[str]:
    a, b = pd.read_parquet(before), pd.read_parquet(after)
    if list(a.columns) != list(b.columns) or list(a.dtypes) != list(b.dtypes):
        return [f"columns differ: {dict(a.dtypes)} vs {dict(b.dtypes)}"]
    if len(a) != len(b):
        return [f"{len(a)} rows vs {len(b)} rows"]
    try:
        pd.testing.assert_frame_equal(a, b, check_exact=True)
    except AssertionError as exc:
        return [f"values differ: {str(exc).splitlines()[0]}"]
    return []


def compare(before: Path, after: Path) -> bool:
    ok = True

    def report(name: str, problems: list[str], extra: str = "") -> None:
        nonlocal ok
        ok &= not problems
        print(f"{'same' if not problems else 'DIFFERENT'}  {name}{extra}")
        for p in problems[:20]:
            print(f"    {p}")

    table = Path("results", "results.parquet")
    identical = (before / table).read_bytes() == (after / table).read_bytes()
    rows = len(pd.read_parquet(before / table))
    report(str(table), compare_tables(before / table, after / table),
           f"  ({rows} rows; files {'byte-identical' if identical else 'differ in bytes only'})")
    meta = Path("aligned", "aligned.json")
    a = _normalise(json.loads((before / meta).read_text()), str(before), str(after))
    b = _normalise(json.loads((after / meta).read_text()), str(before), str(after))
    report(str(meta), _diff(a, b), f"  ({len(a)} top-level keys)")
    indexes = sorted(p.relative_to(before) for p in before.glob("session/**/frames.csv")) + [Path("aligned/frames.csv")]
    for rel in indexes:
        other = after / rel
        same = other.exists() and (before / rel).read_bytes() == other.read_bytes()
        report(str(rel), [] if same else ["not byte-identical (a frame's bytes changed)"])
    return ok


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("before", type=Path)
    p.add_argument("after", type=Path)
    args = p.parse_args(argv)
    ok = compare(args.before.resolve(), args.after.resolve())
    print("identical" if ok else "DIFFERENT")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
