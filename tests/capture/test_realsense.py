"""RealSense through the real SDK, without a camera.

* conversions (intrinsics, extrinsics) checked against librealsense's own projection functions;
* the Must-show round trip: two ``rs.software_device`` cameras (an LQ 640x480 and an HQ 512x424
  stand-in) fed with synthetic frames, each recorded by ``rs.recorder`` into a real ``.db3``,
  imported into one session by ``depthbench capture import realsense`` and compared exactly:
  frame numbers, timestamps, pixels, intrinsics, depth units, extrinsics, device info, metadata;
* bad input: truncated / corrupt / non-database files, a recording without depth, an existing output;
* the live driver with no camera connected.
"""
from __future__ import annotations

import json
import os
import sqlite3

import numpy as np
import pandas as pd
import pyrealsense2 as rs
import pytest

from capture.camera import Transform
from capture.drivers.base import SensorConfig, StreamSettings
from capture.drivers.realsense import RealSenseDriver, intrinsics_from_rs, recorded_frame_counts, transform_from_rs
from capture.errors import CalibrationError, DeviceError, RigError
from capture.session import decode_depth, open_session
from tests.capture.realsense_synth import SynthSpec, record_synthetic
from tests.capture.inproc_cli import run_inproc
from tests.conftest import assert_one_line_error

LQ = SynthSpec()
HQ = SynthSpec(name="Intel RealSense L515", serial="f0245678", firmware="1.5.8.1", depth_size=(512, 424),
               color_size=(640, 360), depth_units=0.00025,
               depth_intrinsics=(365.5, 365.25, 255.75, 211.5, "none", (0.0,) * 5),
               color_intrinsics=(460.5, 460.25, 320.25, 180.75, "brown_conrady", (0.03125, -0.0625, 0.0, 0.0, 0.0)),
               angle=-0.02, translation=(-0.0125, 0.0025, 0.001),
               depth_frame_numbers=[1, 2, 3, 4], color_frame_numbers=[31, 32, 33, 34], t0_us=987_654_321,
               period_us=33_334, domain="global_time", time_of_arrival_ms=1_700_000_000_040)


def _intr(w, h, fx, fy, ppx, ppy, model, coeffs):
    i = rs.intrinsics()
    i.width, i.height, i.fx, i.fy, i.ppx, i.ppy = w, h, fx, fy, ppx, ppy
    i.model = getattr(rs.distortion, model)
    i.coeffs = list(coeffs)
    return i


# ----------------------------------------------------------------------------- conversions
def test_brown_conrady_projects_like_librealsense():
    intr = _intr(640, 480, 612.25, 611.5, 318.75, 241.125, "brown_conrady", [0.11, -0.23, 0.0012, -0.0021, 0.07])
    conv = intrinsics_from_rs(intr)
    assert conv.exact and conv.intrinsics.distortion_model == "opencv"
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-0.6, 0.6, 50), rng.uniform(-0.45, 0.45, 50), rng.uniform(0.5, 3, 50)])
    ours = conv.intrinsics.project(pts)
    sdk = np.array([rs.rs2_project_point_to_pixel(intr, list(p)) for p in pts])
    assert np.abs(ours - sdk).max() < 1e-3  # float32 arithmetic in the SDK


@pytest.mark.parametrize("model", ["inverse_brown_conrady", "modified_brown_conrady"])
def test_other_brown_conrady_variants_match_librealsense_within_two_hundredths_of_a_pixel(model):
    coeffs = [-0.0555, 0.0664, -0.0005, 0.0007, -0.0213]  # a D455 colour camera
    intr = _intr(1280, 720, 640.5, 639.75, 643.25, 362.5, model, coeffs)
    conv = intrinsics_from_rs(intr)
    assert not conv.exact and conv.fit_error_px < 0.02
    K = conv.intrinsics
    rng = np.random.default_rng(1)
    uv = np.column_stack([rng.uniform(0, 1279, 40), rng.uniform(0, 719, 40)])
    pts = np.column_stack([K.pixel_to_normalized(uv), np.ones(len(uv))])
    sdk = np.array([rs.rs2_project_point_to_pixel(intr, list(p)) for p in pts])
    assert np.abs(K.project(pts) - sdk).max() < 0.02
    if model == "inverse_brown_conrady":  # the SDK deprojects this model (iteratively)
        sdk = np.array([rs.rs2_deproject_pixel_to_point(intr, list(p), 1.0) for p in uv])[:, :2]
        assert np.abs((K.pixel_to_normalized(uv) - sdk) * [K.fx, K.fy]).max() < 0.02


def test_fisheye_models_are_refused():
    with pytest.raises(CalibrationError, match="fisheye"):
        intrinsics_from_rs(_intr(848, 800, 286.0, 286.0, 424.0, 400.0, "kannala_brandt4", [-0.01, 0.04, -0.04, 0.007, 0]))


def test_extrinsics_are_column_major_like_librealsense():
    R = Transform.from_rotvec([0.1, -0.2, 0.05], [0, 0, 0]).R.astype(np.float32)
    ex = rs.extrinsics()
    ex.rotation = [float(v) for v in R.T.ravel()]
    ex.translation = [0.015, -0.002, 0.0035]
    T = transform_from_rs(ex)
    p = [0.3, -0.1, 1.7]
    assert np.allclose(T.apply(np.array(p)), rs.rs2_transform_point_to_point(ex, p), atol=1e-6)


# ----------------------------------------------------------------------------- the round trip
@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    d = tmp_path_factory.mktemp("rs")
    return record_synthetic(d / "lq.db3", LQ), record_synthetic(d / "hq.db3", HQ)


@pytest.fixture(scope="module")
def imported(recordings, tmp_path_factory):
    import subprocess  # the `cli` fixture is function-scoped; this one runs once for the module
    import sys

    out = tmp_path_factory.mktemp("sessions") / "desk"
    proc = subprocess.run([sys.executable, "-m", "depthbench", "capture", "import", "realsense", *map(str, recordings),
                           "--role", "lq", "--role", "hq", "--out", str(out)], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    return out, proc.stdout


def test_recordings_are_real_ros2_db3_files(recordings):
    lq, _ = recordings
    assert lq.read_bytes()[:16] == b"SQLite format 3\x00"
    counts = recorded_frame_counts(lq)
    assert counts == {(rs.stream.depth, 0): 5, (rs.stream.color, 0): 5}


def test_two_software_devices_round_trip_exactly(imported):
    out, stdout = imported
    assert "imported 18 frames" in stdout
    s = open_session(out, verify="full")
    assert set(s.sensors) == {"lq", "hq"}
    for sid, spec in (("lq", LQ), ("hq", HQ)):
        sensor = s.sensors[sid]
        man = s.manifest["sensors"][sid]
        assert sensor.role == sid
        assert (sensor.model, sensor.serial, man["firmware"]) == (spec.name, spec.serial, spec.firmware)
        # frame numbers and device timestamps (ms doubles in the SDK) come back exactly
        depth = s.frames(sid, "depth")
        assert depth["frame_number"].tolist() == spec.depth_frame_numbers
        assert depth["device_timestamp_us"].tolist() == spec.depth_timestamps_us()
        color = s.frames(sid, "color")
        assert color["frame_number"].tolist() == spec.color_frame_numbers
        assert color["device_timestamp_us"].tolist() == spec.color_timestamps_us()
        # host timestamps: the recorded time of arrival (ms) in µs
        toa = [(spec.time_of_arrival_ms + (t - spec.t0_us) // 1000) * 1000 for t in spec.depth_timestamps_us()]
        assert depth["host_timestamp_us"].tolist() == toa
        # intrinsics and depth unit: the float32 values the SDK stored, written as their shortest decimals
        for stream, size, (fx, fy, ppx, ppy, model, coeffs) in (("depth", spec.depth_size, spec.depth_intrinsics),
                                                                 ("color", spec.color_size, spec.color_intrinsics)):
            K = s.intrinsics(sid, stream)
            assert (K.width, K.height) == size
            assert (K.fx, K.fy, K.cx, K.cy) == (fx, fy, ppx, ppy)
            expected = tuple(coeffs) if model == "brown_conrady" and any(coeffs) else ()
            assert K.coeffs == expected
            assert K.distortion_model == ("opencv" if expected else "none")
        assert s.stream(sid, "depth").depth_unit_m == spec.depth_units
        assert np.float32(s.stream(sid, "depth").depth_unit_m) == np.float32(spec.depth_units)
        # T_depth_color is the inverse of the registered depth->colour extrinsics. The SDK's recorder
        # keeps them to float32 precision only (sin 0.01 = 0.009999833 plays back as 0.01), so 1e-6.
        T_color_depth = Transform.from_rt(spec.rotation_matrix(), spec.translation)
        assert sensor.T_depth_color.is_close(T_color_depth.inverse(), atol=1e-6)
        assert not sensor.T_depth_color.is_close(T_color_depth, atol=1e-3)  # the direction matters
        # pixels, exactly
        for i, n in enumerate(spec.depth_frame_numbers):
            raw = s.read_image(sid, "depth", n)
            assert np.array_equal(raw, spec.depth_image(i))
            m = s.read_depth(sid, n)
            assert np.array_equal(np.isnan(m), spec.depth_image(i) == 0)
            assert np.allclose(m, decode_depth(spec.depth_image(i), spec.depth_units), equal_nan=True)
        for i, n in enumerate(spec.color_frame_numbers):
            assert np.array_equal(s.read_color(sid, n), spec.color_image(i))
        assert man["clock"]["domains"] == [spec.domain]


def test_drops_metadata_and_provenance_are_recorded(imported):
    out, _ = imported
    man = json.loads((out / "session.json").read_text())
    assert man["sensors"]["lq"]["streams"]["depth"]["dropped_frames"] == 1  # 102 -> 104
    assert man["sensors"]["hq"]["streams"]["depth"]["dropped_frames"] == 0
    assert man["time_base"] == "device"
    files = man["source"]["files"]
    assert [f["sensor"] for f in files] == ["lq", "hq"] and all(len(f["sha256"]) == 64 for f in files)
    assert man["source"]["notes"]["lq"]["host_timestamps"] == "time_of_arrival"
    md = pd.read_csv(out / "lq" / "frame_metadata.csv")
    depth = md[md["stream"] == "depth"]
    assert depth["frame_counter"].tolist() == LQ.depth_frame_numbers
    assert depth["frame_timestamp"].tolist() == LQ.depth_timestamps_us()
    assert depth["sensor_timestamp"].tolist() == [t - 500 for t in LQ.depth_timestamps_us()]
    assert set(depth["clock_domain"]) == {"hardware_clock"}


def test_imported_session_validates(imported, cli):
    out, _ = imported
    r = cli("capture", "validate", out)
    assert r.returncode == 0, r.stderr
    assert "every frame checked" in r.stdout


def test_duplicate_frame_numbers_are_removed_and_counted(tmp_path):
    from capture.importers import import_realsense

    f = record_synthetic(tmp_path / "dup.db3", SynthSpec(depth_frame_numbers=[5, 6, 6, 7, 9], with_color=False))
    result = import_realsense([f], tmp_path / "s")
    rep = result.streams["lq"]["depth"]
    assert (rep.frames, rep.duplicates, rep.dropped) == (4, 1, 1)
    s = open_session(tmp_path / "s")
    assert s.frames("lq", "depth")["frame_number"].tolist() == [5, 6, 7, 9]
    assert s.manifest["sensors"]["lq"]["streams"]["depth"]["duplicate_frames"] == 1


# ----------------------------------------------------------------------------- bad input
def _snapshot(folder):
    return {p: p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_truncated_recording_is_one_line_error(recordings, tmp_path, cli):
    bad = tmp_path / "trunc.db3"
    data = recordings[0].read_bytes()
    bad.write_bytes(data[: len(data) // 2])
    r = cli("capture", "import", "realsense", bad, "--out", tmp_path / "s")
    assert_one_line_error(r, str(bad), "corrupt or truncated")
    assert not (tmp_path / "s").exists() and not list(tmp_path.glob(".s.*"))


def test_corrupt_frame_data_is_detected(recordings, tmp_path, capfd):
    """A damaged image message inside an intact database: the SDK delivers fewer frames than recorded."""
    bad = tmp_path / "blob.db3"
    bad.write_bytes(recordings[0].read_bytes())
    con = sqlite3.connect(bad)
    mid, data = con.execute("SELECT m.id, m.data FROM messages m JOIN topics t ON t.id = m.topic_id "
                            "WHERE t.name LIKE '%Depth_0/image/data%' ORDER BY m.id LIMIT 1 OFFSET 2").fetchone()
    data = bytearray(data)
    data[100::97] = bytes(b ^ 0xFF for b in data[100::97])
    con.execute("UPDATE messages SET data = ? WHERE id = ?", (bytes(data), mid))
    con.commit()
    con.close()
    r = run_inproc(capfd, "capture", "import", "realsense", bad, "--out", tmp_path / "s")
    assert_one_line_error(r, str(bad), "recorded depth frames")
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize("content,message", [(b"", "empty file"), (b"#ROSBAG V2.0\n" + b"\0" * 100, "ROS1 .bag"),
                                             (b"hello", "not an SQLite")])
def test_not_a_recording_is_one_line_error(tmp_path, capfd, content, message):
    bad = tmp_path / "x.db3"
    bad.write_bytes(content)
    r = run_inproc(capfd, "capture", "import", "realsense", bad, "--out", tmp_path / "s")
    assert_one_line_error(r, str(bad), message)


def test_recording_without_depth_is_one_line_error(tmp_path, capfd):
    f = record_synthetic(tmp_path / "color_only.db3", SynthSpec(with_depth=False))
    r = run_inproc(capfd, "capture", "import", "realsense", f, "--out", tmp_path / "s")
    assert_one_line_error(r, str(f), "no depth stream")
    assert not (tmp_path / "s").exists()


def test_existing_output_is_not_overwritten(recordings, imported, tmp_path, capfd):
    out = tmp_path / "existing"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    before = _snapshot(out)
    r = run_inproc(capfd, "capture", "import", "realsense", recordings[0], "--out", out)
    assert_one_line_error(r, str(out), "--force")
    assert _snapshot(out) == before
    r = run_inproc(capfd, "capture", "import", "realsense", recordings[0], "--out", out, "--force", "--quiet")
    assert r.returncode == 0, r.stderr
    assert not (out / "keep.txt").exists() and open_session(out).sensors["lq"].serial == LQ.serial


def test_mismatched_roles_are_one_line_error(recordings, tmp_path, capfd):
    r = run_inproc(capfd, "capture", "import", "realsense", *recordings, "--role", "lq", "--role", "hq", "--role", "view",
            "--out", tmp_path / "s")
    assert_one_line_error(r, "3 roles for 2 recordings")


# ----------------------------------------------------------------------------- the live driver, no camera
def _config(**kw):
    base = dict(id="lq", role="lq", driver="realsense", serial="123456789012",
                streams={"depth": StreamSettings("depth", "depth", 640, 480, 30)})
    base.update(kw)
    return SensorConfig(**base)


def test_no_camera_enumerates_none_and_open_fails_clearly():
    assert RealSenseDriver.enumerate() == []
    drv = RealSenseDriver(_config(sync={"inter_cam_sync_mode": 1}))
    with pytest.raises(DeviceError) as exc:
        drv.open()
    msg = str(exc.value)
    assert "123456789012" in msg and "connected: none" in msg and "\n" not in msg
    drv.close()  # safe after a failed open


@pytest.mark.parametrize("kw,fragment", [
    (dict(sync={"inter_cam_sync_mode": 7000}), "0-260"),
    (dict(sync={"genlock": 1}), "unknown RealSense sync setting"),
    (dict(options={"no_such_option": 1}), "unknown RealSense option"),
    (dict(options={"global_time": 1}), "true or false"),
    (dict(streams={"depth": StreamSettings("depth", "color")}), "must have type 'depth'"),
])
def test_rig_settings_are_checked_before_any_device_is_opened(kw, fragment):
    with pytest.raises(RigError, match=fragment):
        RealSenseDriver.check_config(_config(**kw))
    RealSenseDriver.check_config(_config(sync={"inter_cam_sync_mode": 2}, options={"global_time": True,
                                                                                  "emitter_enabled": 1}))


def test_frame_source_reads_a_playback_device_like_a_live_one(recordings):
    """The live driver's frame source (non-blocking queue, host clock stamps) on a playback device."""
    from capture.drivers.base import host_clock_us
    from capture.drivers.realsense import _STOP, RealSenseSource

    ctx = rs.context()
    dev = ctx.load_device(str(recordings[1]))
    dev.as_playback().set_real_time(False)
    dev.as_playback().pause()
    src = RealSenseSource(dev, {"depth": StreamSettings("depth", "depth", 512, 424, 30)}, label="hq")
    assert set(src.description.streams) == {"depth"} and src.description.streams["depth"].depth_unit_m == 0.00025
    t0 = host_clock_us()
    src.start()
    dev.as_playback().resume()
    got = []
    while len(got) < len(HQ.depth_frame_numbers):
        item = src.get(10.0)
        assert item is not None and item is not _STOP
        got.append(item)
    src.close()
    assert [f.frame_number for f in got] == HQ.depth_frame_numbers
    assert all(f.host_timestamp_us >= t0 and f.clock_domain == "global_time" for f in got)
    assert all(f.metadata["frame_counter"] == f.frame_number for f in got)
    assert os.environ.get("PYTEST_CURRENT_TEST")  # ran inside pytest


def test_live_driver_records_through_the_recorder_from_a_played_recording(recordings, tmp_path, capfd):
    """``options.file`` plays a .db3 in real time through the live driver's code (open/read/close)."""
    lq, hq = recordings
    rig = tmp_path / "rig.toml"
    rig.write_text(f'name = "rs"\n[[sensor]]\nid = "lq"\nrole = "lq"\ndriver = "realsense"\nserial = "{LQ.serial}"\n'
                   f'[sensor.options]\nfile = "{lq}"\n[[sensor]]\nid = "hq"\nrole = "hq"\ndriver = "realsense"\n'
                   f'serial = "*"\n[sensor.options]\nfile = "{hq}"\n[sensor.streams.depth]\ntype = "depth"\n'
                   f'[[sensor]]\nid = "lq2"\nrole = "view"\ndriver = "realsense"\nserial = "*"\n[sensor.options]\n'
                   f'file = "{lq}"\n[sensor.streams.color]\ntype = "color"\nencoding = "jpeg"\n')
    r = run_inproc(capfd, "capture", "record", "--rig", rig, "--out", tmp_path / "rec", "--quiet")
    assert r.returncode == 0, r.stderr
    s = open_session(tmp_path / "rec", verify="full")
    assert set(s.sensors["hq"].streams) == {"depth"} and s.intrinsics("hq", "depth").fx == 365.5
    assert s.stream("lq2", "color").encoding == "jpeg" and s.stream("lq", "color").encoding == "png"
    n = int(s.frames("lq2", "color")["frame_number"].iloc[0])
    jpeg = s.read_color("lq2", n).astype(int)
    i = LQ.color_frame_numbers.index(n)
    errors = [np.abs(jpeg - LQ.color_image(j)).mean() for j in range(len(LQ.color_frame_numbers))]
    assert int(np.argmin(errors)) == i and errors[i] < 0.7 * sorted(errors)[1]  # lossy, but that image (noise)
    # real-time playback may skip a frame when the SDK runs late (it is real time, like a camera);
    # whatever arrives keeps its number and timestamp, and every gap is reported as a drop
    for sid, stream, spec in (("lq", "depth", LQ), ("lq", "color", LQ), ("hq", "depth", HQ)):
        numbers = spec.depth_frame_numbers if stream == "depth" else spec.color_frame_numbers
        times = dict(zip(numbers, spec.depth_timestamps_us() if stream == "depth" else spec.color_timestamps_us()))
        df = s.frames(sid, stream)
        got = df["frame_number"].tolist()
        assert len(got) >= 2 and set(got) <= set(numbers)
        assert df["device_timestamp_us"].tolist() == [times[n] for n in got]
        assert s.manifest["sensors"][sid]["streams"][stream]["dropped_frames"] == got[-1] - got[0] + 1 - len(got)
        host, dev = df["host_timestamp_us"].to_numpy(), df["device_timestamp_us"].to_numpy()
        # host arrival times only go forward; their spacing is not asserted: a loaded machine makes the
        # SDK's real-time playback deliver late frames in a burst, exactly as a late camera would
        assert np.all(np.diff(host) >= 0) and host[-1] > host[0]
    for i, n in enumerate(LQ.depth_frame_numbers):
        if n in s.frames("lq", "depth")["frame_number"].tolist():
            assert np.array_equal(s.read_image("lq", "depth", n), LQ.depth_image(i))


def test_played_recording_must_match_the_serial(recordings, tmp_path):
    drv = RealSenseDriver(_config(serial="999", options={"file": str(recordings[0])}))
    with pytest.raises(DeviceError, match="is of camera 000000000001, not 999"):
        drv.open()
    drv.close()
