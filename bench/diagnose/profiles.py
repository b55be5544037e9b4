"""Sensor profiles for the simulator from diagnosis reports: ``capture/sim/sensor_profiles.json``.

    python -m bench.diagnose.profiles D435=REPORT_D435 D415=REPORT_D415 ... --out capture/sim/sensor_profiles.json

Each ``REPORT`` is a folder written by ``depthbench bench diagnose CAPTURE --out REPORT --sim-to-real``;
its ``diagnosis.json`` holds, per sensor, the fitted parameters and the noise model kept after
the sim-to-real stages (each effect kept only where it brought the simulated twin closer without
making any statistic worse, on the mean over a few twins: ``bench.diagnose.twin.TWIN_SEEDS``). The profile is that kept model, with its provenance: the capture,
the stages kept and rejected, the fitted values with their errors, and the distances; and
``native_focal_px``, the focal length (px) of the pixels the parameters are given in (the stereo
matcher's), which ``capture.sim.noise.sensor_profile(name, focal_px=...)`` converts from.
"""
from __future__ import annotations

import argparse
import json
import sys
from datetime import datetime, timezone
from pathlib import Path

from bench.errors import BenchError
from depthbench.fsutil import atomic_write_text, check_output_free

_KEEP = ("stereo", "tof")


def profile_from_report(name: str, report: Path) -> dict:
    """One profile from a report folder (the first sensor with a simulated twin)."""
    path = report / "diagnosis.json"
    try:
        diag = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise BenchError(f"{path}: not a diagnosis report ({exc})") from None
    s2r = diag.get("sim_to_real") or {}
    sensor = next((k for k, v in s2r.items() if v.get("final")), None)
    if sensor is None:
        raise BenchError(f"{path}: no sim-to-real stages (run 'bench diagnose' with the sim-to-real option)")
    final, d = s2r[sensor]["final"], diag["sensors"][sensor]
    params = {k: v for k, v in final.items() if k not in ("sigma_z",)}
    keep = ("subpixel_px", "subpixel_px_error", "floor_quadratic_subpixel_px", "noise_floor_m", "fB_px_m",
            "correlation_px", "outlier_fraction", "fill_rate", "sigma_linear_a_m", "sigma_linear_b", "board_model",
            "board_params")
    native = d["derived"].get("native_focal_px") or (d["derived"].get("fB_px_m") or 0) / (params.get("baseline_m") or 1)
    if not native:
        raise BenchError(f"{path}: no native focal length of {sensor} (re-run 'bench diagnose' on the capture)")
    return {"model": params["model"], "native_focal_px": float(native), "params": params, "provenance": {
        "capture": diag["source"], "sensor": sensor, "sensor_model": d["model"], "report": str(report),
        "reference": d["reference"], "frames": d["frames"], "sigma_model_chosen": d["sigma_models"]["chosen"],
        "fitted": {k: d["derived"][k] for k in keep if k in d["derived"]},
        "stages": s2r[sensor]["notes"], "kept_stage": s2r[sensor]["final_stage"],
        "distances": s2r[sensor]["values"],
        "distance_standard_errors": s2r[sensor].get("standard_errors"), "twin_seeds": s2r[sensor].get("twin_seeds"),
        "written": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.diagnose.profiles", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("reports", nargs="+", metavar="NAME=REPORT", help="profile name and its diagnosis report folder")
    ap.add_argument("--out", required=True, help="profiles JSON to write")
    ap.add_argument("--force", action="store_true", help="replace an existing --out")
    args = ap.parse_args(argv)
    try:
        check_output_free(Path(args.out), force=args.force, what="profiles file")
        out = {}
        for item in args.reports:
            name, sep, folder = item.partition("=")
            if not sep:
                raise BenchError(f"{item}: expected NAME=REPORT")
            out[name] = profile_from_report(name, Path(folder))
        atomic_write_text(Path(args.out), json.dumps(out, indent=1, sort_keys=False) + "\n")
    except BenchError as exc:
        print(f"python -m bench.diagnose.profiles: error: {exc}", file=sys.stderr)
        return 2
    print(f"{args.out}: {', '.join(out)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
