"""``depthbench capture import {realsense,azure-kinect,tum} ... --out DIR``: recordings into session folders."""
from __future__ import annotations

import argparse

from capture.errors import CaptureError
from depthbench.fsutil import check_output_outside

_EPILOG = ("The session is built under a temporary name and appears only when complete; an existing --out is "
           "replaced only with --force. Check the result with 'depthbench capture validate DIR'.")


def add_parser(sub) -> None:
    p = sub.add_parser("import", help="import a RealSense .db3, Azure Kinect .mkv or TUM RGB-D folder as a session",
                       description="Convert a recording into a session folder, with every frame, timestamp, "
                                   "frame number and the device's calibration.", epilog=_EPILOG)
    kinds = p.add_subparsers(dest="kind", metavar="KIND", parser_class=type(p))
    kinds.required = True

    rs = kinds.add_parser(
        "realsense", help="RealSense recordings (.db3: the ROS2 format librealsense 2.59 records)",
        description="Play RealSense recordings through pyrealsense2 (not real time: every frame) into one "
                    "session, one sensor per file: depth (required), colour and infrared with frame counters, "
                    "timestamps and their clock domain, per-frame metadata (SENSOR/frame_metadata.csv), factory "
                    "intrinsics, depth scale and depth-to-colour extrinsics. The import fails if the SDK delivers "
                    "fewer frames than the file holds.",
        epilog="Example: depthbench capture import realsense d415.db3 l515.db3 --role lq --role hq --out sessions/desk. "
               + _EPILOG)
    rs.add_argument("files", nargs="+", metavar="FILE.db3", help="recording(s), one camera each")
    rs.add_argument("--out", required=True, metavar="DIR", help="session folder to create")
    rs.add_argument("--role", action="append", choices=("lq", "hq", "view"), metavar="ROLE",
                    help="lq, hq or view: once for all files or once per file, in order (default lq)")
    rs.add_argument("--sensor-id", action="append", metavar="ID",
                    help="sensor id per file, in order (default: the role; role + index when roles repeat)")
    rs.add_argument("--streams", default=None, metavar="LIST",
                    help="comma-separated streams to import when present: depth,color,ir,ir2 (default all; depth always)")
    rs.add_argument("--time-base", choices=("device", "host"), default="device",
                    help="timestamps alignment pairs frames by: device = frame timestamps (default), "
                         "host = time of arrival recorded with each frame")
    _common(rs)
    rs.set_defaults(func=run_realsense)

    ak = kinds.add_parser(
        "azure-kinect", help="Azure Kinect recordings (.mkv of k4arecorder)",
        description="Read an Azure Kinect Matroska recording with PyAV: DEPTH (mm) and IR tracks (16-bit "
                    "big-endian), COLOR (MJPG or raw), device timestamps (file time + K4A_START_OFFSET_NS), and "
                    "intrinsics and depth-to-colour extrinsics from the embedded factory calibration.json.",
        epilog="Example: depthbench capture import azure-kinect take1.mkv --out sessions/take1-hq. " + _EPILOG)
    ak.add_argument("file", metavar="FILE.mkv", help="the recording")
    ak.add_argument("--out", required=True, metavar="DIR", help="session folder to create")
    ak.add_argument("--role", choices=("lq", "hq", "view"), default="hq", help="sensor role (default hq)")
    ak.add_argument("--sensor-id", default=None, metavar="ID", help="sensor id (default: the role)")
    ak.add_argument("--streams", default="depth,color,ir", metavar="LIST",
                    help="comma-separated streams to import when present: depth,color,ir (default all; depth always)")
    _common(ak)
    ak.set_defaults(func=run_azure_kinect)

    tum = kinds.add_parser(
        "tum", help="TUM RGB-D benchmark folders (rgb.txt, depth.txt, rgb/, depth/)",
        description="Read a TUM RGB-D folder: the lists' decimal-second timestamps become int µs, depth PNG "
                    "counts / --depth-scale are metres, colour and depth share the given intrinsics "
                    "(depth is registered to colour).",
        epilog="Example: depthbench capture import tum rgbd_dataset_freiburg1_xyz --out sessions/fr1-xyz "
               "--intrinsics 517.3,516.5,318.6,255.3,0.2624,-0.9531,-0.0054,0.0026,1.1633. " + _EPILOG)
    tum.add_argument("folder", metavar="DIR", help="the TUM folder (holds rgb.txt and depth.txt)")
    tum.add_argument("--out", required=True, metavar="DIR", help="session folder to create")
    tum.add_argument("--role", choices=("lq", "hq", "view"), default="lq", help="sensor role (default lq)")
    tum.add_argument("--sensor-id", default=None, metavar="ID", help="sensor id (default: the role)")
    tum.add_argument("--intrinsics", default=None, metavar="FX,FY,CX,CY[,K1,K2,P1,P2[,K3]]",
                     help="camera model of both streams in pixels (default TUM's 525,525,319.5,239.5), "
                          "distortion in OpenCV order")
    tum.add_argument("--size", default="640x480", metavar="WxH", help="image size (default 640x480)")
    tum.add_argument("--depth-scale", type=float, default=5000.0, metavar="COUNTS_PER_M",
                     help="depth PNG counts per metre (default 5000)")
    tum.add_argument("--fps", type=float, default=30.0, help="nominal frame rate (default 30)")
    tum.add_argument("--no-color", action="store_true", help="import depth only")
    _common(tum)
    tum.set_defaults(func=run_tum)


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--name", default=None, help="session name (default: the --out folder name)")
    p.add_argument("--force", action="store_true", help="replace an existing --out folder")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")


def _streams(text: str | None, allowed: tuple[str, ...]) -> tuple[str, ...] | None:
    if text is None:
        return None
    names = tuple(s.strip() for s in text.split(",") if s.strip())
    bad = [n for n in names if n not in allowed]
    if bad or not names:
        raise CaptureError(f"--streams: unknown stream {bad[0] if bad else text!r} (choose from {','.join(allowed)})")
    return tuple(dict.fromkeys(("depth",) + names))


def _report(result, args) -> int:
    if not args.quiet:
        print(result.summary())
    return 0


def run_realsense(args) -> int:
    from capture.importers import import_realsense

    check_output_outside(args.out, args.files, what="session folder")
    result = import_realsense(args.files, args.out, sensor_ids=args.sensor_id, roles=args.role,
                              streams=_streams(args.streams, ("depth", "color", "ir", "ir2")),
                              time_base=args.time_base, name=args.name, force=args.force, progress=not args.quiet)
    return _report(result, args)


def run_azure_kinect(args) -> int:
    from capture.importers import import_azure_kinect

    check_output_outside(args.out, [args.file], what="session folder")
    result = import_azure_kinect(args.file, args.out, sensor_id=args.sensor_id or args.role, role=args.role,
                                 streams=_streams(args.streams, ("depth", "color", "ir")), name=args.name,
                                 force=args.force, progress=not args.quiet)
    return _report(result, args)


def _intrinsics(text: str | None, size: str):
    from capture.camera import Intrinsics
    from capture.drivers.tum import DEFAULT_INTRINSICS

    try:
        w, h = (int(v) for v in size.lower().split("x"))
    except ValueError:
        raise CaptureError(f"--size: expected WxH like 640x480, got {size!r}") from None
    if text is None:
        return DEFAULT_INTRINSICS if (w, h) == (640, 480) else DEFAULT_INTRINSICS.scaled(w, h)
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        raise CaptureError(f"--intrinsics: expected comma-separated numbers, got {text!r}") from None
    if len(v) not in (4, 8, 9):
        raise CaptureError(f"--intrinsics: give FX,FY,CX,CY and optionally K1,K2,P1,P2[,K3] ({len(v)} numbers given)")
    coeffs = tuple(v[4:])
    return Intrinsics(w, h, v[0], v[1], v[2], v[3], "opencv" if any(coeffs) else "none",
                      coeffs if any(coeffs) else ())


def run_tum(args) -> int:
    from capture.importers import import_tum

    check_output_outside(args.out, [args.folder], what="session folder")
    result = import_tum(args.folder, args.out, sensor_id=args.sensor_id or args.role, role=args.role,
                        intrinsics=_intrinsics(args.intrinsics, args.size), depth_scale=args.depth_scale, fps=args.fps,
                        with_color=not args.no_color, name=args.name, force=args.force, progress=not args.quiet)
    return _report(result, args)
