"""``depthbench bench diagnose DATA --out REPORT``: a thin parser over :func:`bench.diagnose.run.run_diagnose`."""
from __future__ import annotations

import argparse

_EPILOG = """\
DATA is a session folder (the simulator's truth/ is the reference when present), an aligned dataset
(LQ depth against the warped HQ reference), an Azure Kinect .mkv, or one of the real captures of
../shared/data/real (alr_d435_charuco, vcl3d_d415, azure_kinect_pyk4a, tum_kinect1_sample, ddrnet_person).

examples:
  depthbench bench diagnose ../shared/data/real/alr_d435_charuco --out diag_d435/
  depthbench bench diagnose sim_session/ --out diag_sim/ --max-frames 30
  depthbench bench diagnose ../shared/data/real/vcl3d_d415 --out diag_d415/ --sim-to-real
"""


def add_parser(sub) -> None:
    p = sub.add_parser("diagnose", help="measure a depth sensor's error model (noise, bias, fill, edges) with plots",
                       description="Measure each depth sensor's error model against a reference (the simulator's "
                                   "truth, a fused reference, a ChArUco board's plane or local planes): random error "
                                   "and bias vs depth with fitted candidate models chosen on held-out data, fill rate "
                                   "vs depth/brightness/texture, spatial correlation, depth-edge errors, quantisation. "
                                   "Writes REPORT/report.md, one PNG per sensor and diagnosis.json.",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", metavar="DATA", help="session, aligned dataset, .mkv or real-capture folder")
    p.add_argument("--out", required=True, metavar="REPORT", help="report folder to create")
    p.add_argument("--max-frames", type=int, default=60, metavar="N",
                   help="at most N evenly spaced frames per sensor (default 60)")
    p.add_argument("--sim-to-real", action="store_true",
                   help="also diagnose the simulated twin of the capture and report the distance per statistic")
    p.add_argument("--force", action="store_true", help="replace an existing REPORT folder")
    p.set_defaults(func=_diagnose)


def _diagnose(args) -> int:
    from bench.diagnose.run import run_diagnose

    if args.max_frames < 1:
        raise SystemExit("depthbench bench diagnose: error: --max-frames: must be at least 1")
    res = run_diagnose(args.data, args.out, force=args.force, max_frames=args.max_frames,
                       sim_to_real=args.sim_to_real)
    for name, d in res.result.sensors.items():
        der = d.derived
        extra = f", subpixel {der['subpixel_px']:.3f} px" if "subpixel_px" in der else ""
        print(f"{name}: sigma model {d.sigma_models.chosen}, fill {d.fill_rate:.3f}{extra}")
    print(f"report: {res.report}")
    return 0
