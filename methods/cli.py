"""``depthbench methods ...``: list the methods, run one on an aligned dataset.

    depthbench methods list [--json]
    depthbench methods run NAME --data ALIGNED --out DIR [--param k=v ...] [--force]

``run`` writes the denoised LQ depth in the session's on-disk convention (uint16 PNG in the
dataset's depth unit, 0 = none) plus ``denoised.json`` (method key, version, parameters, dataset
checksum); the format is described in :mod:`methods.output`. The library function behind ``run``
is :func:`methods.run.denoise_dataset` (it says what happens to a frame a method cannot process).
"""
from __future__ import annotations

import json
import math

from methods.errors import MethodError
from methods.registry import aliases_of, available, get
from methods.run import denoise_dataset


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "methods", help="list depth-denoising methods, run one on an aligned dataset",
        description="Depth-denoising methods behind one interface: classical filters (bilateral, joint "
                    "bilateral, rolling guidance, Gaussian), the identity 'raw', and learned methods.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=type(parser))
    sub.required = True

    p = sub.add_parser("list", help="every method with its parameters, defaults and description",
                       description="Print every registered method: name, version, what it does, and each "
                                   "parameter with its default and meaning (units included).")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run_list)

    p = sub.add_parser(
        "run", help="denoise the LQ depth of an aligned dataset",
        description="Run method NAME on every frame of an aligned dataset and write the denoised depth "
                    "(uint16 PNG in the dataset's depth unit, 0 = none) and denoised.json to --out. A frame without "
                    "valid depth is written empty; a frame the method refuses stops the run with an error naming "
                    "it, and nothing is written (the same rule as 'bench run').",
        epilog="Example: depthbench methods run bilateral --data A --out D --param sigma_color=0.02 "
               "--param depth_adaptive=true.  Parameter values: numbers, true/false, none, inf.")
    p.add_argument("name", help="method name (see 'depthbench methods list')")
    p.add_argument("--data", required=True, help="aligned dataset folder (from 'depthbench align')")
    p.add_argument("--out", required=True, help="output folder (created; refused if it exists unless --force)")
    p.add_argument("--param", action="append", default=[], metavar="K=V",
                   help="override a parameter, e.g. sigma_spatial=2.5 (repeatable)")
    p.add_argument("--force", action="store_true", help="replace an existing output folder")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_run)

    from methods.train_cli import add_parsers

    add_parsers(sub)


# ----------------------------------------------------------------------------- parameters
def parse_value(text: str):
    """``none`` -> None, ``true``/``false`` -> bool, integers, floats (``inf`` too), else the string."""
    low = text.strip().lower()
    if low in ("none", "null"):
        return None
    if low in ("true", "yes", "on"):
        return True
    if low in ("false", "no", "off"):
        return False
    try:
        return int(low)
    except ValueError:
        pass
    try:
        return float(low)
    except ValueError:
        return text


def parse_params(items: list[str]) -> dict:
    params: dict = {}
    for item in items:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise MethodError(f"--param {item!r}: expected NAME=VALUE")
        if key in params:
            raise MethodError(f"--param {key} given twice")
        params[key] = parse_value(value)
    return params


def _fmt(value) -> str:
    if value is None:
        return "none"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and math.isinf(value):
        return "inf"
    return str(value)


# ----------------------------------------------------------------------------- commands
def _listing(name: str, cls) -> dict:
    """One method as ``methods list --json`` shows it."""
    parts = [f"weights file ({cls.weights_param}=PATH)"] if cls.needs_weights() else []
    needs = ", ".join(parts + [p for p in [cls.declared_needs().describe()] if p])
    return {"name": name, "aliases": aliases_of(name), "version": cls.version, "description": cls.description,
            "learned": cls.learned, "uses_color": cls.uses_color, "sequential": cls.sequential,
            "needs": needs or "depth only", "params": [{"name": k, "default": v, "help": cls.param_help.get(k, "")}
                                                       for k, v in cls.defaults.items()]}


def run_list(args) -> int:
    entries = [_listing(n, c) for n, c in available().items()]
    if args.json:
        print(json.dumps(entries, indent=2))
        return 0
    for e in entries:
        tags = [f"alias {a}" for a in e["aliases"]] + [t for t, on in (
            ("learned", e["learned"]), ("uses colour", e["uses_color"]), ("sequence", e["sequential"])) if on]
        print(f"{e['name']}  (version {e['version']}{', ' + ', '.join(tags) if tags else ''})")
        print(f"    {e['description']}")
        print(f"    needs: {e['needs']}")
        if not e["params"]:
            print("    no parameters")
        width = max((len(p["name"]) for p in e["params"]), default=0)
        for p in e["params"]:
            print(f"    {p['name']:<{width}} = {_fmt(p['default']):<8} {p['help']}")
        print()
    print("Run one with: depthbench methods run NAME --data ALIGNED --out DIR [--param K=V ...]")
    return 0


def run_run(args) -> int:
    from depthbench.fsutil import check_output_outside

    check_output_outside(args.out, [args.data], what="denoised output")
    method = get(args.name, **parse_params(args.param))
    result = denoise_dataset(method, args.data, args.out, force=args.force,
                             progress=False if args.no_progress else None)
    empty = f" ({result.empty} without valid depth, written empty)" if result.empty else ""
    print(f"{result.method_key}: {result.frames} frames{empty} -> {result.out}")
    return 0
