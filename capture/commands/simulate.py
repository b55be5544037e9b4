"""``depthbench capture simulate``: write a simulated RGB-D session with ground truth."""
from __future__ import annotations

import argparse

from capture.sim import EFFECTS, RIGS, SCENES

EPILOG = """effects (--effect NAME=VALUE, repeatable; they act on the LQ sensor unless noted):
  clock_drift_ppm       [-1000, 1000]  LQ host clock runs fast (+) or slow (-) against HQ
  depth_scale           [0.5, 2]       LQ depth multiplied by this factor
  depth_offset_mm       [-200, 200]    LQ depth offset (after the scale): z' = s z + o
  distortion_k1         [-0.5, 0.5]    uncorrected radial lens distortion k1 of the LQ camera
  hq_distortion_k1      [-0.5, 0.5]    radial lens distortion k1 of the HQ colour camera
  rolling_shutter_ms    [0, 60]        LQ colour camera's rolling-shutter readout time
  frame_drop_rate       [0, 0.9]       probability that any frame of any sensor is dropped
  frame_duplicate_rate  [0, 0.5]       probability that an LQ frame repeats its predecessor's image
Declared effects are written to session.json; with --undeclared only to truth/truth.json.

sensor profiles (--lq-profile / --hq-profile NAME): noise models measured on real captures by
'depthbench bench diagnose' (capture/sim/sensor_profiles.json); their pixel parameters are
converted to the simulated image's focal length (--scale included), so the depth error is the
real sensor's; the profile is recorded in session.json (sensors.X.noise.profile) and truth/.

example:
  depthbench capture simulate --rig lq-hq --scene people --seconds 3 --seed 1 --out sim1 \\
      --effect depth_scale=1.02 --undeclared
  depthbench capture simulate --rig lq-hq --seconds 3 --out sim2 --lq-profile D435 --hq-profile "Azure Kinect"
"""


def add_parser(sub) -> None:
    p = sub.add_parser(
        "simulate", help="simulate an RGB-D rig filming a moving scene, with ground truth in truth/",
        description="Ray-cast a moving scene (walking figures, balloons, or textured planes) with simulated "
                    "sensors (stereo LQ, time-of-flight HQ), add their noise, clocks and dropped frames, and "
                    "write a session folder plus truth/ (noise-free depth, poses, clocks, time shift).",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="session folder to create")
    p.add_argument("--rig", choices=RIGS, default="lq-hq", help="sensor rig (default: %(default)s)")
    p.add_argument("--scene", choices=SCENES, default="people", help="scene content (default: %(default)s)")
    p.add_argument("--seconds", type=float, default=5.0, help="scene time to simulate, s (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="random seed; same seed, same bytes (default: %(default)s)")
    p.add_argument("--effect", action="append", default=[], metavar="NAME=VALUE",
                   help=f"switch on an effect ({', '.join(EFFECTS)}); repeatable")
    p.add_argument("--undeclared", action="store_true",
                   help="record the effects in truth/ only, not in session.json (later stages must find them)")
    p.add_argument("--time-shift-ms", type=float, default=None, metavar="MS",
                   help="true LQ-vs-HQ host clock shift in ms (default: drawn within +-55 ms, inside the alignment's +-60 ms search)")
    p.add_argument("--frame-phase-ms", type=float, default=None, metavar="MS",
                   help="how long after each HQ frame the LQ frame is exposed, ms, within one LQ frame period "
                        "either way: how far apart a pair's frames fall (default: drawn with the seed)")
    p.add_argument("--static", action="store_true", help="nothing moves (the time shift is then unobservable)")
    p.add_argument("--scale", type=float, default=1.0,
                   help="multiply every image size, e.g. 0.25 for quick runs (default: %(default)s)")
    p.add_argument("--lq-fps", type=float, default=30.0, help="frame rate of the LQ / view sensors (default: %(default)s)")
    p.add_argument("--hq-fps", type=float, default=30.0, help="frame rate of the HQ sensor (default: %(default)s)")
    p.add_argument("--lq-profile", default=None, metavar="NAME",
                   help="noise of the LQ / view sensors from a measured sensor profile (D435, D415, Kinect v1; "
                        "capture/sim/sensor_profiles.json; default: the built-in D415-like model)")
    p.add_argument("--hq-profile", default=None, metavar="NAME",
                   help="noise of the HQ sensor from a measured time-of-flight profile (Azure Kinect; "
                        "default: the built-in Kinect v2 / Azure-like model)")
    p.add_argument("--color-format", choices=("auto", "png", "jpeg"), default="auto",
                   help="encoding of the colour streams; auto: PNG for LQ, JPEG for HQ as Azure Kinect records (default: %(default)s)")
    p.add_argument("--workers", type=int, default=None,
                   help="rendering processes (default: 1 on two cores, else one per core up to 4 for long runs; "
                        "the output does not depend on it)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--force", action="store_true", help="replace --out if it exists")
    p.set_defaults(func=run)


def run(args) -> int:
    from capture.sim import simulate   # Open3D: imported only when simulating, not for every command line

    shift = None if args.time_shift_ms is None else round(args.time_shift_ms * 1000)
    r = simulate(args.out, rig=args.rig, scene=args.scene, seconds=args.seconds, seed=args.seed, effects=args.effect,
                 undeclared=args.undeclared, force=args.force, time_shift_us=shift, static=args.static,
                 scale=args.scale, lq_fps=args.lq_fps, hq_fps=args.hq_fps, color_encoding=args.color_format,
                 progress=not args.no_progress, workers=args.workers, lq_profile=args.lq_profile,
                 hq_profile=args.hq_profile,
                 frame_phase_us=None if args.frame_phase_ms is None else args.frame_phase_ms * 1000)
    frames = ", ".join(f"{s}: {n} frames ({r.dropped[s]} dropped)" for s, n in r.frames.items())
    print(f"wrote {r.root} ({r.rig}, {r.scene}, {r.seconds:g} s; {frames}) in {r.elapsed_s:.1f} s "
          f"[{r.scene_frames_per_s:.1f} frames of scene time/s]")
    print(f"ground truth: {r.root / 'truth' / 'truth.json'} (effects "
          f"{'declared in session.json' if r.declared else 'in truth/ only'}: {r.effects or 'none'})")
    return 0
