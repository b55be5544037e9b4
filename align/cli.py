"""``depthbench align SESSION --out ALIGNED``: a thin parser over :func:`align.pipeline.align_session`."""
from __future__ import annotations

import argparse

from align.features import FEATURES
from align.reference_edges import RULES


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "align", help="align HQ and LQ streams in time and space; write an aligned dataset and its report",
        description=(
            "Find the time shift between the HQ and LQ clocks (seed report eq. 28-31: a coarse scan then a "
            "bracketing refinement of the spatial feature loss, sub-millisecond), fit the extrinsic T_lq_hq from "
            "colour features (PnP+RANSAC, then a robust joint least-squares fit), warp the HQ depth onto the LQ "
            "image (z-buffer, both cameras' distortion), and write the aligned dataset (data_manifests/aligned.md) "
            "with report.md/report.html. Multi-view sessions (role 'view') give one dataset per view plus rig.json."),
        epilog="Example: depthbench align sim/ --out aligned/ --shift-range-ms 60 --features sift")
    p.add_argument("session", metavar="SESSION", help="session folder (capture format)")
    p.add_argument("--out", required=True, metavar="ALIGNED", help="aligned dataset folder to create")
    p.add_argument("--force", action="store_true", help="replace ALIGNED if it exists")
    _time_group(p)
    _space_group(p)
    _model_groups(p)
    _output_group(p)
    p.set_defaults(func=run)


def _time_group(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("time")
    g.add_argument("--shift-range-ms", type=float, default=60.0, metavar="MS",
                   help="search the shift in [-MS, +MS] (default: %(default)g)")
    g.add_argument("--shift-step-ms", type=float, default=2.0, metavar="MS",
                   help="coarse scan step before the bracketing refinement (default: %(default)g)")
    g.add_argument("--time-model", choices=("constant", "linear"), default="constant",
                   help="constant shift, or Delta(t) = a + b t with clock drift (default: %(default)s); "
                        "clock facts declared in session.json are used as given")
    g.add_argument("--association", choices=("nearest", "greedy"), default="nearest",
                   help="nearest: eq. 28 per HQ frame; greedy: TUM associate.py one-to-one (default: %(default)s)")
    g.add_argument("--max-dt-ms", type=float, default=None, metavar="MS",
                   help="drop pairs whose time difference after the shift exceeds MS (default: half the LQ period)")
    g.add_argument("--allow-unobservable", action="store_true",
                   help="when the shift cannot be measured (static scene), write the dataset anyway with the declared "
                        "shift or 0, flagged as unobservable, instead of stopping with an error")
    g.add_argument("--no-dejitter", action="store_true",
                   help="use the raw host stamps (default: regularised against the frame counters)")


def _space_group(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("space")
    g.add_argument("--features", choices=FEATURES, default="sift", help="colour feature detector (default: %(default)s)")
    g.add_argument("--max-features", type=int, default=1500, metavar="N", help="keypoints per image (default: %(default)s)")
    g.add_argument("--probes", type=int, default=24, metavar="N",
                   help="HQ frames, spread over the session, whose features fit the shift and T_ex (default: %(default)s)")
    g.add_argument("--no-feature-refinement", action="store_true",
                   help="fit T_ex on the SIFT keypoints as detected, without moving them to where the HQ colour patch "
                        "lies in the LQ image (the refinement takes T_lq_hq's z error from 1-1.5 mm to a few tenths)")
    g.add_argument("--board", metavar="SPEC", default=None,
                   help="take T_ex from a recorded ChArUco board instead of colour features: SXxSY:SQUARE_M:MARKER_M[:DICT], "
                        "e.g. 7x5:0.075:0.06:DICT_4X4_250 (the time shift still comes from features; a still board "
                        "leaves it unobservable: add --allow-unobservable)")
    g.add_argument("--residual-k", type=float, default=6.0, metavar="K",
                   help="drop pairs whose depth residual lies more than K robust sigmas above the median (default: %(default)g)")
    g.add_argument("--reference-edges", choices=tuple(RULES), default="footprint-fg",
                   help="the reference at depth edges: strict extends no surface past its last HQ sample and masks the "
                        "far side of every reference edge (3 px; 2 px for the footprint rules; counted in aligned.json); mixed does the same and also "
                        "masks what the HQ's time-of-flight mixed pixels hide (fewer large errors, more pixels masked); "
                        "midpoint guesses the edge half way and masks nothing; strict-fg and mixed-fg mask as strict and "
                        "mixed but only where the reference is in front of the background, i.e. in the ROI; footprint-fg also masks "
                        "what lies behind the footprint of any HQ sample at an edge, the ones the warp drops included; "
                        "footprint-mixed-fg also leaves out the mixed samples mixed distrusts and masks what they covered "
                        "(lower RMSE, about 3 points more of the ROI masked); footprint-colour-fg also masks reference "
                        "pixels at a silhouette whose LQ colour (co-registered only) looks like the other side "
                        "(default: %(default)s)")


def _model_groups(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("effects (the alignment loop, align/loop)")
    g.add_argument("--no-loop", action="store_true",
                   help="skip the effect loop (drift, rolling shutter, lens, depth scale/offset, duplicated frames)")
    g.add_argument("--keep-lq-depth", action="store_true",
                   help="write the LQ depth as recorded even when the loop finds a depth scale or offset")
    g = p.add_argument_group("motion between unsynchronised frames (align/motion.py)")
    g.add_argument("--no-motion", action="store_true",
                   help="keep the plain warp of the pair's HQ frame as the reference, even when the LQ frame falls "
                        "between two HQ frames (default: the reference is carried to the LQ instant from both)")
    g.add_argument("--motion-min-dt-ms", type=float, default=1.0, metavar="MS",
                   help="pairs closer in time than this keep the plain warp (default: %(default)g)")
    g.add_argument("--motion-model", choices=("edges", "flow"), default="flow",
                   help="how the reference is carried: flow (the HQ frame's points moved along the HQ colour images' "
                        "optical flow, align/motion_flow.py) or edges (crossing times of depth edges, align/motion.py: "
                        "half the time, further from the truth) (default: %(default)s)")
    g = p.add_argument_group("multi-view rigs")
    g.add_argument("--rig-refine", choices=("views", "always", "never"), default="views",
                   help="refine the pairwise feature fits of a multi-view rig jointly from every sensor's static depth "
                        "(align/rig_refine.py): where the reference is a view (no HQ sensor), always, or never "
                        "(default: %(default)s)")
    g.add_argument("--view-sync", choices=("unobservable", "always", "never"), default="unobservable",
                   help="find a view's time shift against the rig's reference from the depth of what moves, given the "
                        "calibrated rig (align/view_sync.py): where colour features could not, for every view, or never "
                        "(default: %(default)s)")


def _output_group(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("output")
    g.add_argument("--no-truth", action="store_true", help="do not attach the simulator's truth depth (simulated sessions)")
    g.add_argument("--no-report", action="store_true", help="skip report.md and the figures")
    g.add_argument("--workers", type=int, default=2, metavar="N", help="threads for feature work (default: %(default)s)")
    g.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    from align.errors import AlignError
    from align.pipeline import align_session
    from depthbench.fsutil import check_output_outside

    check_output_outside(args.out, [args.session], what="aligned dataset")

    if args.workers < 1:
        raise AlignError(f"--workers must be at least 1, got {args.workers}")
    if args.max_features < 50:
        raise AlignError(f"--max-features must be at least 50, got {args.max_features}")
    try:
        r = align_session(
            args.session, args.out, force=args.force, shift_range_ms=args.shift_range_ms,
            shift_step_ms=args.shift_step_ms, features=args.features, max_features=args.max_features,
            probes=args.probes, association=args.association, max_dt_ms=args.max_dt_ms, residual_k=args.residual_k,
            time_model=args.time_model, workers=args.workers,
            on_unobservable="flag" if args.allow_unobservable else "error", attach_truth=not args.no_truth,
            report=not args.no_report, progress=not args.no_progress, dejitter=not args.no_dejitter, board=args.board,
            loop=not args.no_loop, loop_correct_depth=not args.keep_lq_depth, reference_edges=args.reference_edges,
            motion=not args.no_motion, motion_min_dt_ms=args.motion_min_dt_ms, motion_model=args.motion_model,
            rig_refine=args.rig_refine, view_sync=args.view_sync,
            refine_features=not args.no_feature_refinement)
    except AlignError as exc:
        raise _with_flag(exc)
    sh = r.shift
    state = "" if sh.observable else "  (UNOBSERVABLE: placeholder, see the report)"
    print(f"aligned dataset: {r.out}")
    print(f"  time shift: {sh.time_shift_us / 1000:+.3f} ms +- {sh.std_us / 1000:.3f} ms ({sh.model}){state}")
    print(f"  T_lq_hq: rotation {r.T_lq_hq.rotation_angle_deg():.3f} deg, translation "
          f"{1000 * float((r.T_lq_hq.t ** 2).sum() ** 0.5):.1f} mm; feature RMS {r.fit.rms_px:.2f} px")
    if r.rig is not None:
        refined = " refined from static depth" if r.rig.refinement else ""
        print(f"  rig: {len(r.views)} views in the frame of {r.rig.reference}{refined} (rig.json)")
        for w in r.rig.warnings:
            print(f"  WARNING (rig): {w}")
        off = (r.rig.refinement or {}).get("feature_fit_sd_off", {})
        if off:
            print(f"  feature fits off the refined rig: up to {max(off.values()):.1f} sd (4.7 = p 0.001; see the report)")
    loop = getattr(r.views.get(next(iter(r.views), None)), "loop", None) if r.views else None
    if loop is not None:
        found = [f"{f.name} ({', '.join(f'{k} {v:.4g}' for k, v in f.params.items())})" for f in loop.findings]
        print(f"  effects: {'; '.join(found) if found else 'none needed'}"
              + (f"; unexplained: {', '.join(s.name for s in loop.unexplained())}" if loop.unexplained() else ""))
    motion = _motion_line(r.out)
    if motion:
        print(motion)
    dropped = r.dropped if isinstance(r.dropped, dict) else {}
    print(f"  pairs kept: {r.kept}" + (f"; dropped: {dropped}" if dropped else ""))
    if r.report is not None:
        print(f"  report: {r.report}")
    return 0


def _motion_line(out) -> str:
    """One line on the motion compensation from the dataset's aligned.json ('' for multi-view rigs)."""
    import json
    from pathlib import Path

    path = Path(out) / "aligned.json"
    m = json.loads(path.read_text()).get("motion") if path.is_file() else None
    if not m or not m.get("enabled"):
        return "  motion: off" if m else ""
    t = m["time_apart_ms"]
    return (f"  motion: {m['compensated']} of {m['pairs']} pairs carried to the LQ instant (frames "
            f"{t['median']:.1f} ms apart, median); masked {100 * m['masked_share']:.2f} % of reference pixels")


#: AlignOptions fields whose flag is not ``--`` + the name with dashes
_FLAGS = {"on_unobservable": "--allow-unobservable"}


def _with_flag(exc):
    """The library names the option (``exc.option``); the command line names its flag."""
    option = getattr(exc, "option", None)
    if option:
        flag = _FLAGS.get(option, "--" + option.replace("_", "-"))
        exc.args = (f"{flag}: {exc.args[0] if exc.args else ''}",) + tuple(exc.args[1:])
    return exc
