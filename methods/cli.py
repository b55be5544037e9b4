"""``depthbench methods ...``: list the methods, run one on an aligned dataset.

    depthbench methods list [--json]
    depthbench methods run NAME --data ALIGNED --out DIR [--param k=v ...] [--force]

``run`` writes the denoised LQ depth in the session's on-disk convention (uint16 PNG in the
dataset's depth unit, 0 = none) plus ``denoised.json`` (method key, version, parameters, dataset
checksum); the format is described in :mod:`methods.output`.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time

from tqdm import tqdm

from methods.base import available, get
from methods.errors import MethodError
from methods.output import DenoisedWriter


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
                    "(uint16 PNG in the dataset's depth unit, 0 = none) and denoised.json to --out.",
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
def run_list(args) -> int:
    methods = available()
    if args.json:
        out = [{"name": n, "version": c.version, "description": c.description, "learned": c.learned,
                "uses_color": c.uses_color, "params": [{"name": k, "default": v, "help": c.param_help.get(k, "")}
                                                        for k, v in c.defaults.items()]}
               for n, c in methods.items()]
        print(json.dumps(out, indent=2))
        return 0
    for n, c in methods.items():
        tags = [t for t, on in (("learned", c.learned), ("uses colour", c.uses_color)) if on]
        print(f"{n}  (version {c.version}{', ' + ', '.join(tags) if tags else ''})")
        print(f"    {c.description}")
        if not c.defaults:
            print("    no parameters")
        width = max((len(k) for k in c.defaults), default=0)
        for k, v in c.defaults.items():
            print(f"    {k:<{width}} = {_fmt(v):<8} {c.param_help.get(k, '')}")
        print()
    print("Run one with: depthbench methods run NAME --data ALIGNED --out DIR [--param K=V ...]")
    return 0


def run_run(args) -> int:
    from align.dataset import AlignedDataset   # methods may import align (geometry, data); bench may not be imported

    method = get(args.name, **parse_params(args.param))
    data = AlignedDataset(args.data)
    if len(data) == 0:
        raise MethodError(f"{args.data}: the aligned dataset has no frames")
    if method.uses_color and data.lq_color(0) is None:
        raise MethodError(f"{method.name} needs the LQ colour image, and {args.data} has none")
    started = time.perf_counter()
    writer = DenoisedWriter(args.out, method, dataset_checksum=data.checksum, dataset_name=data.name,
                            dataset_path=str(args.data), depth_unit_m=data.depth_unit_m, force=args.force)
    try:
        for i in tqdm(range(len(data)), desc=f"{method.name}", unit="frame", file=sys.stderr, leave=False,
                      disable=True if args.no_progress else None):
            depth = data.lq_depth(i)
            color = data.lq_color(i) if method.uses_color else None
            try:
                out = method.denoise(depth, color, data.lq_intrinsics)
            except MethodError as exc:
                raise MethodError(f"{args.data}: frame {i}: {exc}") from None
            writer.add(i, out)
        root = writer.close(seconds=time.perf_counter() - started)
    except BaseException as exc:
        writer.abort(exc)
        raise
    print(f"{method.key}: {len(data)} frames -> {root}")
    return 0
