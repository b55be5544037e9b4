"""Simulator throughput: frames of scene time per second for each rig, and where the time goes.

Run:  .venv/bin/python perf/simulate_fps.py [--seconds 3] [--scene people] [--workers N] [--repeat 3]
      .venv/bin/python perf/simulate_fps.py --rigs lq-hq --against-scene people-boxy --repeat 3 --no-reference

For each rig at the default resolutions (lq-hq: 640x480 stereo + 512x424 ToF + 960x540 colour),
it simulates ``--seconds`` of scene time into a temporary folder and prints:

* wall-clock frames of scene time per second (one frame = 1/30 s of every stream),
* CPU milliseconds per frame (user + system of the main and worker processes, from
  ``os.times``), and the CPU-bound rate ``cores * 1000 / (cpu ms per frame)``: what the wall
  rate reaches when nothing else runs on the machine and the workers keep every core busy,
* milliseconds per frame per stage, summed over the rendering processes (``perf_counter``
  inside each stage, so they include waiting for a core on a busy machine): ``raycast``
  (Open3D / Embree), ``shade`` (texture, shading, colour exposure kernels), ``noise`` (depth
  noise models), ``encode`` (PNG/JPEG), and the main process's ``write`` (files, index rows).

The reference in the same run is the straightforward renderer on ``lq-hq``: one process,
every pixel cast every frame (no still layer), encoding after rendering, printed first; the
ratios compare against it. The default for ``lq-hq`` (one process on 2 cores, encoding in a
thread while the next frame renders) is also compared with 2 worker processes.
The machine is shared while the suite is developed, so the load average is printed too.

``--against-scene S``: for each rig, runs of ``--scene`` and of ``S`` alternate (``--repeat``
pairs, so a load change on a shared machine hits both alike) and the ratio of the two is printed
(issue 13: the smooth ``people`` figures against the earlier ``people-boxy`` ones).

``--against-tree DIR`` (with ``--against-scene S``): the runs of ``S`` use the code in ``DIR``, a
checkout of an earlier commit (e.g. ``git archive 40ab985 | tar -x -C DIR``), so that one run
compares today's simulator on ``--scene`` with the earlier simulator on ``S``. Every run of both
is then a fresh process (a short warm-up simulation first, so numba's compiled-kernel cache and
Open3D's start are not counted), its CPU time measured around the run itself.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from capture.sim import RIGS, simulate

STAGES = ("raycast", "shade", "noise", "encode", "write")


def _cpu_seconds() -> float:
    """CPU seconds (user + system) of this process and of its finished children (the workers)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _run(out: Path, rig: str, args, *, workers: int | None, reference: bool = False) -> dict:
    """Best of ``args.repeat`` runs (highest wall rate; the machine may be shared)."""
    runs = [_run_once(out, rig, args, workers=workers, reference=reference) for _ in range(args.repeat)]
    best = max(runs, key=lambda m: m["fps"])
    best["cpu_per_frame_ms"] = min(m["cpu_per_frame_ms"] for m in runs)
    return best


def _run_once(out: Path, rig: str, args, *, workers: int | None, reference: bool = False,
              scene: str | None = None) -> dict:
    cpu0 = _cpu_seconds()
    r = simulate(out, rig=rig, scene=scene or args.scene, seconds=args.seconds, seed=1, force=True, progress=False,
                 workers=workers, reference=reference)
    frames = args.seconds * 30.0
    return {"fps": r.scene_frames_per_s, "wall": r.elapsed_s,
            "per_frame_ms": {s: 1e3 * r.timings_s.get(s, 0.0) / frames for s in STAGES},
            "cpu_per_frame_ms": 1e3 * (_cpu_seconds() - cpu0) / frames}


#: One run in a fresh process, with the code on its PYTHONPATH (``--against-tree``); argv[1]: JSON options.
_ONE_RUN = """
import json, os, shutil, sys, tempfile
from capture.sim import simulate
a = json.loads(sys.argv[1])
tmp = tempfile.mkdtemp(prefix="simulate-fps-")
kw = dict(rig=a["rig"], scene=a["scene"], seed=1, force=True, progress=False, workers=a["workers"])
try:
    simulate(os.path.join(tmp, "warm"), seconds=0.2, **kw)
    cpu = lambda t: t.user + t.system + t.children_user + t.children_system
    c0 = cpu(os.times())
    r = simulate(os.path.join(tmp, "run"), seconds=a["seconds"], **kw)
    print(json.dumps({"fps": r.scene_frames_per_s, "wall": r.elapsed_s, "timings_s": r.timings_s,
                      "cpu_s": cpu(os.times()) - c0}))
finally:
    shutil.rmtree(tmp, ignore_errors=True)
"""


def _run_in_tree(tree: Path, rig: str, args, *, scene: str) -> dict:
    """One run of ``scene`` in a fresh process with the code of ``tree``."""
    opts = json.dumps({"rig": rig, "scene": scene, "seconds": args.seconds, "workers": args.workers})
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, "-c", _ONE_RUN, opts], env=env, cwd=tree, check=True, capture_output=True,
                         text=True).stdout
    r = json.loads(out.strip().splitlines()[-1])
    frames = args.seconds * 30.0
    return {"fps": r["fps"], "wall": r["wall"],
            "per_frame_ms": {s: 1e3 * r["timings_s"].get(s, 0.0) / frames for s in STAGES},
            "cpu_per_frame_ms": 1e3 * r["cpu_s"] / frames}


def _print(label: str, m: dict, ref: dict | None, cores: int) -> None:
    cpu_fps = 1e3 / m["cpu_per_frame_ms"] * cores
    stages = " ".join(f"{s} {m['per_frame_ms'][s]:.0f}" for s in STAGES)
    ratio = f" | vs reference: x{m['fps'] / ref['fps']:.2f} wall, x{ref['cpu_per_frame_ms'] / m['cpu_per_frame_ms']:.2f} cpu" \
        if ref else ""
    print(f"{label:<30} {m['fps']:5.1f} frames/s wall ({m['wall']:5.1f} s) | cpu {m['cpu_per_frame_ms']:4.0f} ms/frame "
          f"-> {cpu_fps:5.1f} frames/s on {cores} idle cores | stage ms/frame: {stages}{ratio}")


def _against(out: Path, rig: str, args, cores: int) -> None:
    """``--scene`` against ``--against-scene`` on ``rig``, runs alternated; best of each, and the ratio."""
    here = Path(__file__).resolve().parents[1]
    sides = {"this": (args.scene, here), "against": (args.against_scene, args.against_tree)}
    labels = {"this": f"scene {args.scene}", "against": f"scene {args.against_scene}"
              + (f" (code in {args.against_tree})" if args.against_tree else "")}
    runs: dict[str, list[dict]] = {side: [] for side in sides}
    for _ in range(args.repeat):
        for side, (scene, tree) in sides.items():
            runs[side].append(_run_in_tree(here if tree is None else tree, rig, args, scene=scene)
                              if args.against_tree else _run_once(out, rig, args, workers=args.workers, scene=scene))
    best = {}
    for side, ms in runs.items():
        best[side] = max(ms, key=lambda m: m["fps"]) | {"cpu_per_frame_ms": min(m["cpu_per_frame_ms"] for m in ms)}
        _print(f"{rig}, {labels[side]}", best[side], None, cores)
        print("    cpu ms/frame of each run: " + ", ".join(f"{m['cpu_per_frame_ms']:.0f}" for m in ms))
    a, b = best["this"], best["against"]
    print(f"{rig}: {labels['this']} / {labels['against']}: x{a['fps'] / b['fps']:.3f} wall rate, "
          f"x{b['cpu_per_frame_ms'] / a['cpu_per_frame_ms']:.3f} cpu rate (> 1: the first is faster)")


def _reference(out: Path, args) -> dict:
    """lq-hq the straightforward way: every pixel cast every frame, encode after render, one process."""
    return _run(out, "lq-hq", args, workers=1, reference=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seconds", type=float, default=3.0, help="scene time per rig (default %(default)s)")
    p.add_argument("--scene", default="people")
    p.add_argument("--workers", type=int, default=None, help="rendering processes (default: the simulator's)")
    p.add_argument("--rigs", nargs="*", default=list(RIGS))
    p.add_argument("--repeat", type=int, default=1, help="runs per configuration; the best wall rate is shown")
    p.add_argument("--no-reference", action="store_true", help="skip the slow reference run")
    p.add_argument("--against-scene", default=None, metavar="S",
                   help="compare --scene with scene S on each rig, runs alternated (e.g. people-boxy)")
    p.add_argument("--against-tree", type=Path, default=None, metavar="DIR",
                   help="run the --against-scene runs with the code in DIR (an earlier checkout)")
    args = p.parse_args()
    if args.against_tree and not args.against_scene:
        p.error("--against-tree needs --against-scene")
    if args.against_tree and not (args.against_tree / "capture" / "sim").is_dir():
        p.error(f"--against-tree: {args.against_tree} holds no capture/sim package")
    cores = os.cpu_count() or 1
    print(f"cores: {cores}  load average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}  "
          f"scene: {args.scene}, {args.seconds:g} s = {args.seconds * 30:.0f} frames of scene time per rig")
    tmp = Path(tempfile.mkdtemp(prefix="simulate-fps-"))
    try:
        ref = None
        if not args.no_reference:
            ref = _reference(tmp / "ref", args)
            _print("reference: lq-hq, naive", ref, None, cores)
        for rig in args.rigs:
            if args.against_scene:
                _against(tmp / rig, rig, args, cores)
                continue
            m = _run(tmp / rig, rig, args, workers=args.workers)
            _print(f"{rig}, {'default' if args.workers is None else args.workers} workers", m, ref, cores)
            if rig == "lq-hq" and args.workers is None:
                _print("lq-hq, 2 worker processes", _run(tmp / "two", rig, args, workers=2), ref, cores)
        print(f"(after the runs: load average {' '.join(f'{x:.2f}' for x in os.getloadavg())})")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
