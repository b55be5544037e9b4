"""ChArUco board path (synthetic rendered board, and the real D435 board images) and multi-view rigs."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from align.charuco import BoardSpec, board_pose, detect_board, extrinsics_from_boards
from capture.camera import Intrinsics, Transform

SPEC = BoardSpec(7, 5, 0.04, 0.032)


def _view_board(spec: BoardSpec, K: Intrinsics, T_cam_board: Transform, px_per_square=200, margin=100, ss=4):
    """Render the board as camera K sees it at pose T_cam_board: the board image mapped through the
    plane's homography onto a camera ``ss`` times finer, then area-averaged down (no aliasing)."""
    img = spec.render(px_per_square, margin)
    s = spec.square_m / px_per_square  # metres per board-image pixel
    A = np.array([[s, 0, (0.5 - margin) * s], [0, s, (0.5 - margin) * s], [0, 0, 1.0]])  # pixel centres
    Kf = K.scaled(K.width * ss, K.height * ss)
    H = Kf.K @ np.column_stack([T_cam_board.R[:, 0], T_cam_board.R[:, 1], T_cam_board.t]) @ A
    fine = cv2.warpPerspective(img, H, (Kf.width, Kf.height), flags=cv2.INTER_LINEAR, borderValue=110)
    return cv2.resize(fine, (K.width, K.height), interpolation=cv2.INTER_AREA)


def test_board_pose_on_a_rendered_board():
    K = Intrinsics(1280, 720, 900.0, 900.0, 639.5, 359.5)
    T = Transform.from_rotvec([0.25, -0.3, 0.05], [-0.12, -0.06, 0.75])
    img = _view_board(SPEC, K, T)
    xy, ids = detect_board(img, SPEC)
    assert len(ids) == (SPEC.squares_x - 1) * (SPEC.squares_y - 1)
    p = board_pose(xy, ids, SPEC, K)
    dt, dr = p.T_cam_board.error_to(T)
    assert dt < 0.002 and dr < 0.2 and p.rms_px < 0.5, (dt, dr, p.rms_px)


def test_extrinsics_from_boards_between_two_cameras():
    Ka = Intrinsics(960, 540, 700.0, 700.0, 479.5, 269.5)
    Kb = Intrinsics(640, 480, 600.0, 600.0, 319.5, 239.5)
    T_b_a = Transform.from_rotvec([0.01, -0.04, 0.005], [0.125, 0.01, -0.006])
    pa, pb = [], []
    for rv, t in (([0.2, 0.1, 0.0], [-0.1, -0.05, 0.7]), ([-0.3, 0.2, 0.1], [-0.05, -0.1, 0.8]),
                  ([0.1, -0.35, -0.05], [-0.15, -0.02, 0.65])):
        T_a_board = Transform.from_rotvec(rv, t)
        T_b_board = T_b_a @ T_a_board
        for K, T, out in ((Ka, T_a_board, pa), (Kb, T_b_board, pb)):
            xy, ids = detect_board(_view_board(SPEC, K, T), SPEC)
            out.append(board_pose(xy, ids, SPEC, K).T_cam_board)
    T_a_b, spread = extrinsics_from_boards(pa, pb)
    dt, dr = T_a_b.inverse().error_to(T_b_a)
    assert dt < 0.002 and dr < 0.1 and spread["views"] == 3, (dt, dr)


def test_no_board_is_a_clear_error():
    from align.errors import CalibrationBoardError

    K = Intrinsics(320, 240, 300.0, 300.0, 159.5, 119.5)
    xy, ids = detect_board(np.full((240, 320), 128, np.uint8), SPEC)
    assert len(ids) == 0
    with pytest.raises(CalibrationBoardError, match="corners"):
        board_pose(xy, ids, SPEC, K)
    with pytest.raises(Exception, match="--board"):
        BoardSpec.parse("7x5")


def test_board_pose_on_real_d435_images_agrees_with_depth(real_data):
    """Real ChArUco images (alr D435, depth aligned to colour, mm): the board plane from the pose
    and from a plane fit to the depth agree in orientation, and the square length the depth implies
    is the same in the mid and far poses (the board's physical size is not documented)."""
    root = real_data / "alr_d435_charuco"
    K = Intrinsics(1920, 1080, 1377.64, 1375.72, 936.48, 537.49)
    spec = BoardSpec(7, 5, 1.0, 0.8, "DICT_4X4_250")  # unit squares: the pose's scale is fitted below
    scales, angles = {}, {}
    for f in (0, 6, 27):
        img = cv2.cvtColor(cv2.imread(str(root / "color" / f"{f}.png")), cv2.COLOR_BGR2RGB)
        xy, ids = detect_board(img, spec)
        assert len(ids) >= 15, (f, len(ids))
        p = board_pose(xy, ids, spec, K)
        assert p.rms_px < 1.5, (f, p.rms_px)
        depth = cv2.imread(str(root / "depth" / f"{f}.png"), cv2.IMREAD_UNCHANGED).astype(np.float32) / 1000
        hull = cv2.convexHull(xy.astype(np.float32)).astype(np.int32)
        mask = np.zeros(depth.shape, np.uint8)
        cv2.fillConvexPoly(mask, hull, 1)
        mask = cv2.erode(mask, np.ones((15, 15), np.uint8)).astype(bool) & (depth > 0.2) & (depth < 3)
        P = K.depth_to_points(np.where(mask, depth, np.nan)).reshape(-1, 3)
        P = P[np.all(np.isfinite(P), axis=1)]
        keep = np.ones(len(P), bool)
        for _ in range(5):  # robust plane fit (the sensor has far outliers)
            c = P[keep].mean(axis=0)
            n = np.linalg.svd(P[keep] - c, full_matrices=False)[2][2]
            r = (P - c) @ n
            keep = np.abs(r) < 3 * 1.4826 * np.median(np.abs(r[keep])) + 1e-4
        n_pose = p.T_cam_board.R[:, 2]
        angles[f] = float(np.degrees(np.arccos(min(1.0, abs(n @ n_pose)))))
        scales[f] = float(abs(c @ n) / abs(p.T_cam_board.t @ n_pose))
    assert max(angles.values()) < 8, angles
    assert abs(scales[6] - scales[27]) / scales[27] < 0.03, scales
    assert all(0.05 < s < 0.1 for s in scales.values()), scales  # squares of ~7.5 cm


@pytest.fixture(scope="module")
def multiview(tmp_path_factory):
    from align.pipeline import align_session
    from tests.align.conftest import simulate_session

    root = simulate_session(tmp_path_factory.mktemp("mv") / "mv", rig="multiview4-hq", seconds=2.0, seed=5, scale=0.5)
    out = tmp_path_factory.mktemp("mva") / "aligned"
    res = align_session(root, out, progress=False, probes=16, report=True, on_unobservable="flag")
    return root, out, res


def test_multiview_rig_in_one_frame(multiview):
    root, out, res = multiview
    truth = json.loads((root / "truth" / "truth.json").read_text())
    rig = json.loads((out / "rig.json").read_text())
    ref = truth["reference_sensor"]
    assert rig["reference"] == ref == "hq"
    assert set(rig["T_rig_sensor"]) == {"hq", "view0", "view1", "view2", "view3"}
    errors = []
    for v, p in truth["pairs"].items():
        if v == ref:
            continue
        T_fit = Transform.from_list(rig["T_rig_sensor"][v]).inverse()  # T_view_ref
        dt, dr = T_fit.error_to(Transform.from_list(p["T_sensor_reference"]))
        # half resolution and 2 s: looser than the 2 mm / 0.1 deg shown at full resolution
        # (bench/perf/align_accuracy.py)
        assert dt < 0.006 and dr < 0.1, (v, dt, dr)
        # the rig is consistent: view-to-view transforms composed through the rig frame
        T_v0 = Transform.from_list(rig["T_rig_sensor"]["view0"]).inverse() @ Transform.from_list(rig["T_rig_sensor"][v])
        T_v0_true = Transform.from_list(truth["pairs"]["view0"]["T_sensor_reference"]) @ \
            Transform.from_list(p["T_sensor_reference"]).inverse()
        assert T_v0.error_to(T_v0_true)[0] < 0.012
        meta = json.loads((out / v / "aligned.json").read_text())
        # wide baselines at half resolution: few moving matches (a shift from depth: the next test)
        if meta["time_model"]["observable"] and meta["time_model"]["kind"] != "depth":
            errors.append(rig["time_shift_us"][v] - p["time_shift_us"])
    # The shift comes from the few features on moving figures (40-150 per view here). Measured on
    # seeds 5 and 6 x 4 views (issue 13, docs/worklog/2026-11-23/s13-sensor.md): with the faceted
    # figures the RMS error is 1.01 ms (largest 1.4 ms; stated std 0.48 ms), with the smooth ones
    # 1.37 ms (largest 2.6 ms, view1 of seed 5; stated std 0.56 ms): smooth shading has no facet
    # corners to track, 23 % fewer moving features, so the shift is less observable. The earlier
    # 2 ms per view was twice the RMS error even for the faceted figures (about 5 % of views past it).
    # Here: per view 4 ms (3 x the RMS error), and 2.5 ms RMS over the views (chi-square, 4 views:
    # about 1 % of seeds past it); a frame off (33 ms) or a wrong peak still fails.
    assert errors and all(abs(e) < 4000 for e in errors), errors
    assert np.sqrt(np.mean(np.square(errors))) < 2500, errors
    for v in ("view0", "view1", "view2", "view3"):
        assert (out / v / "aligned.json").is_file() and (out / v / "report.md").is_file()
    assert (out / "report.md").is_file()
    assert "refinement" not in rig  # an HQ reference keeps its feature fits (AlignOptions.rig_refine = "views")


def test_multiview_rig_refined_from_static_depth_within_its_sd(multiview, tmp_path):
    """align.rig_refine on the simulator's five-sensor rig (the fits of the fixture): every sensor
    within its stated sd of the simulator's extrinsics, the sds not vacuous, the checks reported."""
    from align.pipeline import refine_multiview_rig
    from capture.session import open_session

    root, out, res = multiview
    truth = json.loads((root / "truth" / "truth.json").read_text())
    rig = refine_multiview_rig(open_session(root), res.views, res.rig, progress=False)
    for v, p in truth["pairs"].items():
        if v == truth["reference_sensor"]:
            continue
        dt, dr = rig.T_rig_sensor[v].inverse().error_to(Transform.from_list(p["T_sensor_reference"]))
        sd_t, sd_r = rig.std[v]
        # 3-D norm against sqrt(trace): chi with 3 dof, 99.9 % below 2.2x
        assert dt < 2.2 * sd_t and dr < 2.2 * sd_r, (v, dt, dr, rig.std[v])
        assert dt < 0.012 and dr < 0.15 and sd_t < 0.012 and sd_r < 0.15, (v, dt, dr, rig.std[v])
    ref = rig.refinement
    assert len(ref["pairs"]) == 10 and ref["dof"] >= 24 and ref["consistent"], ref["warnings"]
    assert set(ref["feature_fit_sd_off"]) == {"view0", "view1", "view2", "view3"}
    assert all(T.is_close(res.rig.T_rig_sensor[s]) for s, T in rig.T_rig_sensor_features.items())
    # what rig.json and the rig report carry
    from types import SimpleNamespace

    from align.report import write_rig_report

    d = json.loads(json.dumps(rig.to_dict()))
    assert set(d["T_rig_sensor_std"]) == set(d["T_rig_sensor"]) == set(d["T_rig_sensor_features"])
    assert d["refinement"]["pairs"][0]["correspondences"] > 500
    md = write_rig_report(tmp_path, open_session(root), rig, res.views,
                          {v: SimpleNamespace(kept=1) for v in res.views}).read_text()
    assert "loop check chi2" in md and "| hq - view0 |" in md and "feature fit off the rig (sd)" in md
    assert "WARNING" not in md


def test_multiview_view_shifts_from_depth_against_the_simulators(multiview):
    """align.view_sync through the product (``sync_multiview_views``, every view) on the simulator's
    five-sensor rig: each view's shift within 4 ms of the simulator's (a frame is 33 ms), and where
    the alignment took it from depth (feature shift unobservable), aligned.json carries it."""
    import copy

    import pandas as pd

    from align.pipeline import AlignOptions, pair_frames, sync_multiview_views
    from capture.session import open_session

    root, out, res = multiview
    truth = json.loads((root / "truth" / "truth.json").read_text())
    fits = {v: copy.copy(pf) for v, pf in res.views.items()}   # the fixture's fits keep their shifts
    syncs = sync_multiview_views(open_session(root), fits, res.rig, AlignOptions(view_sync="always", progress=False))
    assert set(syncs) == {"view0", "view1", "view2", "view3"}
    for v, y in syncs.items():
        err = y.time_shift_us - truth["pairs"][v]["time_shift_us"]
        assert y.observable and abs(err) < 4000 and abs(err) < 4 * y.std_us + 1000, (v, err, y.std_us, y.reason)
        assert fits[v].shift.model == "depth" and fits[v].shift.time_shift_us == y.time_shift_us
        # the product's pairing at that shift: every pair's frames exposed within half a period (plus
        # the shift's error) of each other in scene time, i.e. the nearest exposures
        st = fits[v].setup
        table = pair_frames(st, fits[v], AlignOptions(progress=False))
        scene = {s: dict(zip(df["frame_number"], df["scene_time_us"]))
                 for s, df in ((s, pd.read_csv(root / "truth" / s / "frames.csv")) for s in (st.hq, st.lq))}
        kept = np.flatnonzero(table.kept)
        gap = [scene[st.lq][int(st.f_lq[table.lq_index[k]])] - scene[st.hq][int(st.f_hq[table.hq_index[k]])] for k in kept]
        assert kept.size > 40 and np.max(np.abs(gap)) < st.lq_period_us / 2 + abs(err) + 1000, (v, np.max(np.abs(gap)))
    rig = json.loads((out / "rig.json").read_text())
    for v in syncs:
        meta = json.loads((out / v / "aligned.json").read_text())
        if meta["time_model"]["kind"] == "depth":
            assert rig["time_sync"][v]["observable"] and meta["time_shift_us"] == rig["time_shift_us"][v]
            assert abs(meta["time_shift_us"] - truth["pairs"][v]["time_shift_us"]) < 4000
            assert f"| {v} (from hq) | {meta['time_shift_us'] / 1000:.3f} (depth) |" in (out / "report.md").read_text()


def _board_session(root, spec, T_lq_hq, T_hqd_hqc):
    """A hand-written session: a textured wall, a ChArUco board moved in front of it, seen by an LQ
    camera (colour = depth) and an HQ camera (depth + its own colour camera), both at 30 fps."""
    from capture.session import SessionWriter
    from tests.align.scene import Plane, Rect, cast, texture

    K_lq = Intrinsics(640, 480, 600.0, 600.0, 319.5, 239.5)
    K_hd = Intrinsics(512, 424, 365.0, 365.0, 255.5, 211.5)
    K_hc = Intrinsics(960, 540, 530.0, 530.0, 479.5, 269.5)

    def stream(K, kind):
        d = {"type": kind, "width": K.width, "height": K.height, "fps": 30.0, "encoding": "png16" if kind == "depth" else "png",
             "intrinsics": K.to_dict()}
        if kind == "depth":
            d["depth_unit_m"] = 0.001
        return d

    manifest = {"name": "board", "time_base": "host", "clock_facts": {"time_shift_us": 0},
                "sensors": {"lq": {"role": "lq", "model": "test", "serial": "1", "streams": {"depth": stream(K_lq, "depth"),
                                   "color": stream(K_lq, "color")}, "T_depth_color": Transform.identity().to_list()},
                            "hq": {"role": "hq", "model": "test", "serial": "2", "streams": {"depth": stream(K_hd, "depth"),
                                   "color": stream(K_hc, "color")}, "T_depth_color": T_hqd_hqc.to_list()}}}
    wall = Plane((0, 0, 2.5), (0, 0, 1))
    T_world_lq = Transform.identity()
    T_world_hqd = T_world_lq @ T_lq_hq
    cams = {("lq", "depth"): (K_lq, T_world_lq), ("lq", "color"): (K_lq, T_world_lq),
            ("hq", "depth"): (K_hd, T_world_hqd), ("hq", "color"): (K_hc, T_world_hqd @ T_hqd_hqc)}
    with SessionWriter(root, manifest) as w:
        for k in range(12):
            T_w_board = Transform.from_rotvec([0.15 * np.sin(k), 0.25 * np.cos(k), 0.05], [-0.3 + 0.01 * k, -0.2, 1.2])
            corner = T_w_board.apply(np.array([[0, 0, 0]]))[0]
            ex, ey = T_w_board.R[:, 0], T_w_board.R[:, 1]
            w_, h_ = spec.squares_x * spec.square_m, spec.squares_y * spec.square_m
            board = Rect(tuple(corner + ex * w_ / 2 + ey * h_ / 2), tuple(ex * w_ / 2), tuple(ey * h_ / 2))
            t_us = 1_000_000 + k * 33_333
            for (sid, kind), (K, T_world_cam) in cams.items():
                T_cam_world = T_world_cam.inverse()
                depth, P, which = cast(K, T_cam_world, [wall, board])
                if kind == "depth":
                    img = depth.astype(np.float32)
                else:
                    img = texture(P)
                    view = _view_board(spec, K, T_cam_world @ T_w_board)
                    on = which == 1
                    img[on] = np.repeat(view[on][:, None], 3, axis=1)
                w.add_frame(sid, kind, k + 1, t_us, t_us, img)
    return root


def test_charuco_path_through_align_session(tmp_path):
    from align.pipeline import align_session

    spec = BoardSpec(7, 5, 0.08, 0.064)
    T_lq_hq = Transform.from_rotvec([0.01, -0.03, 0.004], [0.125, 0.011, -0.006])
    T_hqd_hqc = Transform.from_rotvec([0.002, -0.003, 0.001], [-0.052, 0.001, 0.0006])
    root = _board_session(tmp_path / "board", spec, T_lq_hq, T_hqd_hqc)
    r = align_session(root, tmp_path / "aligned", progress=False, probes=4, board="7x5:0.08:0.064",
                      on_unobservable="flag", report=False, min_matches=12)
    dt, dr = r.T_lq_hq.error_to(T_lq_hq)
    assert dt < 0.003 and dr < 0.15, (dt, dr)
    meta = json.loads((tmp_path / "aligned" / "aligned.json").read_text())
    assert meta["T_lq_hq_source"] == "charuco" and meta["charuco"]["views"] >= 6
