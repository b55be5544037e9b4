"""Azure Kinect recordings: the real k4arecorder file in shared/data/real/azure_kinect_pyk4a/.

The calibration is checked against numbers computed here from ``calibration.json`` on disk
(the SDK's mode-specific rule written out by hand), the depth against SOURCES.md (640x576 mm,
~77 % valid, median ~1.5 m), and bad files must give one-line errors with nothing written.
"""
from __future__ import annotations

import json

import av
import numpy as np
import pytest

from capture.camera import Transform
from capture.drivers.azure_kinect import open_mkv, parse_calibration
from capture.errors import CalibrationError
from capture.session import open_session
from tests.capture.inproc_cli import run_inproc
from tests.conftest import assert_one_line_error


@pytest.fixture(scope="module")
def ak(real_data):
    folder = real_data / "azure_kinect_pyk4a"
    return folder / "recording.mkv", json.loads((folder / "calibration.json").read_text())


@pytest.fixture(scope="module")
def imported(ak, tmp_path_factory):
    import subprocess
    import sys

    out = tmp_path_factory.mktemp("ak") / "take"
    proc = subprocess.run([sys.executable, "-m", "depthbench", "capture", "import", "azure-kinect", str(ak[0]),
                           "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return out


def _camera(calib, purpose):
    return next(c for c in calib["CalibrationInformation"]["Cameras"] if c["Purpose"] == purpose)


def test_depth_intrinsics_follow_the_sdk_rule(ak, imported):
    _, calib = ak
    p = _camera(calib, "CALIBRATION_CameraPurposeDepth")["Intrinsics"]["ModelParameters"]
    cx, cy, fx, fy, k1, k2, k3, k4, k5, k6, codx, cody, p2, p1 = p
    # NFOV unbinned: 1024x1024 calibration, crop (192, 180), output 640x576, pixel centres at integers
    K = open_session(imported).intrinsics("hq", "depth")
    assert (K.width, K.height) == (640, 576)
    assert K.fx == pytest.approx(fx * 1024, abs=1e-9) and K.fy == pytest.approx(fy * 1024, abs=1e-9)
    assert K.cx == pytest.approx(cx * 1024 - 192 - 0.5, abs=1e-9)
    assert K.cy == pytest.approx(cy * 1024 - 180 - 0.5, abs=1e-9)
    assert K.distortion_model == "opencv"
    assert K.coeffs == pytest.approx((k1, k2, p1, p2, k3, k4, k5, k6), abs=0)  # note: the file stores p2 before p1
    assert 500 < K.fx < 510 and 320 < K.cx < 345  # a plausible NFOV camera


def test_color_intrinsics_and_extrinsics(ak, imported):
    _, calib = ak
    cam = _camera(calib, "CALIBRATION_CameraPurposePhotoVideo")
    cx, cy, fx, fy, k1, k2, k3, k4, k5, k6, codx, cody, p2, p1 = cam["Intrinsics"]["ModelParameters"]
    s = open_session(imported)
    K = s.intrinsics("hq", "color")
    # 720p: the 4096x3072 calibration binned to 1280x960, cropped by 120 rows
    assert (K.width, K.height) == (1280, 720)
    assert K.fx == pytest.approx(fx * 1280) and K.fy == pytest.approx(fy * 960)
    assert K.cx == pytest.approx(cx * 1280 - 0.5) and K.cy == pytest.approx(cy * 960 - 120 - 0.5)
    assert K.coeffs == pytest.approx((k1, k2, p1, p2, k3, k4, k5, k6), abs=0)
    # Rt maps depth-camera points into the colour camera, translation in metres (~32 mm baseline)
    R = np.array(cam["Rt"]["Rotation"]).reshape(3, 3)
    t = np.array(cam["Rt"]["Translation"])
    T = s.sensors["hq"].T_depth_color
    p_depth = np.array([0.1, -0.2, 1.5])
    assert np.allclose(T.inverse().apply(p_depth), R @ p_depth + t, atol=1e-6)
    assert 0.03 < np.linalg.norm(T.t) < 0.035
    assert T.rotation_angle_deg() == pytest.approx(np.degrees(np.arccos((np.trace(R) - 1) / 2)), abs=1e-3)


def test_depth_content_matches_the_sources_notes(imported, ak):
    s = open_session(imported, verify="full")
    sensor = s.sensors["hq"]
    assert (sensor.role, sensor.model, sensor.serial) == ("hq", "Azure Kinect DK", "001514394512")
    assert set(sensor.streams) == {"depth", "color", "ir"}
    assert s.stream("hq", "depth").depth_unit_m == 0.001
    n = int(s.frames("hq", "depth")["frame_number"].iloc[0])
    depth = s.read_depth("hq", n)
    assert depth.shape == (576, 640) and depth.dtype == np.float32
    valid = np.isfinite(depth)
    assert valid.mean() == pytest.approx(0.77, abs=0.01)
    assert np.median(depth[valid]) == pytest.approx(1.5, abs=0.02)
    assert 0.15 < depth[valid].min() < 0.2 and 3.5 < depth[valid].max() < 3.8
    # big-endian decoding: the raw stored counts equal the track's bytes read as >u2
    container = av.open(str(ak[0]))
    packet = next(p for p in container.demux(container.streams[1]) if p.size)
    assert np.array_equal(s.read_image("hq", "depth", n), np.frombuffer(bytes(packet), ">u2").reshape(576, 640))
    color = s.read_color("hq", n)
    assert color.shape == (720, 1280, 3) and 20 < color.mean() < 235


def test_timestamps_are_device_time(imported, ak):
    s = open_session(imported)
    tags = av.open(str(ak[0])).metadata
    offset_us = int(tags["K4A_START_OFFSET_NS"]) // 1000
    for stream in ("depth", "ir", "color"):
        df = s.frames("hq", stream)
        assert df["device_timestamp_us"].tolist() == [463945 + offset_us]  # block time + start offset
        assert df["frame_number"].tolist() == [0]
    man = s.manifest
    assert man["time_base"] == "device"
    assert man["sensors"]["hq"]["clock"]["start_offset_us"] == offset_us
    assert man["sensors"]["hq"]["streams"]["depth"]["fps"] == 5.0


def test_validate_accepts_the_import(imported, cli):
    r = cli("capture", "validate", imported)
    assert r.returncode == 0, r.stderr


def test_calibration_parser_refuses_what_it_cannot_represent(ak):
    _, calib = ak
    text = json.dumps(calib)
    parsed = parse_calibration(text, depth_mode="WFOV_2X2BINNED", color_size=(1920, 1080))
    assert (parsed.depth_intrinsics.width, parsed.depth_intrinsics.height) == (512, 512)
    assert parsed.color_intrinsics.height == 1080
    bad = json.loads(text)
    _camera(bad, "CALIBRATION_CameraPurposeDepth")["Intrinsics"]["ModelType"] = "CALIBRATION_LensDistortionModelRational6KT"
    with pytest.raises(CalibrationError, match="Rational6KT"):
        parse_calibration(json.dumps(bad), depth_mode="NFOV_UNBINNED")
    with pytest.raises(CalibrationError, match="unknown depth mode"):
        parse_calibration(text, depth_mode="NFOV_3X3")
    with pytest.raises(CalibrationError, match="not an Azure Kinect calibration"):
        parse_calibration("{}")


def test_reader_directly(ak):
    rec = open_mkv(ak[0], streams=("depth",))
    frames = list(rec.frames())
    assert [f.stream for f in frames] == ["depth"] and frames[0].image.dtype == np.uint16


# ----------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("keep", [100, 300_000, 1_500_000, -1000])
def test_truncated_recording_is_one_line_error(ak, tmp_path, capfd, cli, keep):
    data = ak[0].read_bytes()
    bad = tmp_path / "cut.mkv"
    bad.write_bytes(data[:keep])
    run = cli if keep == 300_000 else (lambda *a: run_inproc(capfd, *a))  # one real subprocess
    r = run("capture", "import", "azure-kinect", bad, "--out", tmp_path / "s")
    assert_one_line_error(r, str(bad))
    assert any(w in r.stderr for w in ("truncated", "corrupt")), r.stderr
    assert not (tmp_path / "s").exists() and not list(tmp_path.glob(".s.*"))


def test_corrupt_header_is_one_line_error(ak, tmp_path, capfd):
    data = bytearray(ak[0].read_bytes())
    data[:64] = bytes(64)
    bad = tmp_path / "bad.mkv"
    bad.write_bytes(bytes(data))
    r = run_inproc(capfd, "capture", "import", "azure-kinect", bad, "--out", tmp_path / "s")
    assert_one_line_error(r, str(bad))


def test_recording_without_depth_is_one_line_error(ak, tmp_path, capfd):
    """A Matroska file with only the colour track (remuxed from the real one with PyAV)."""
    src = av.open(str(ak[0]))
    path = tmp_path / "color_only.mkv"
    with av.open(str(path), "w", format="matroska") as out:
        for k, v in src.metadata.items():
            out.metadata[k] = v
        o = out.add_stream_from_template(src.streams[0])
        o.metadata["title"] = "COLOR"
        for pkt in src.demux(src.streams[0]):
            if pkt.dts is not None:
                pkt.stream = o
                out.mux(pkt)
    r = run_inproc(capfd, "capture", "import", "azure-kinect", path, "--out", tmp_path / "s")
    assert_one_line_error(r, str(path), "no depth stream")
    assert not (tmp_path / "s").exists()


def test_existing_output_is_not_overwritten(ak, tmp_path, capfd):
    out = tmp_path / "s"
    out.mkdir()
    (out / "session.json").write_text("{}")
    r = run_inproc(capfd, "capture", "import", "azure-kinect", ak[0], "--out", out)
    assert_one_line_error(r, str(out), "--force")
    assert (out / "session.json").read_text() == "{}"


def test_missing_file_is_one_line_error(tmp_path, capfd):
    r = run_inproc(capfd, "capture", "import", "azure-kinect", tmp_path / "nope.mkv", "--out", tmp_path / "s")
    assert_one_line_error(r, "nope.mkv", "no such file")


def test_driver_plays_the_recording(ak):
    from capture.drivers.base import SensorConfig, StreamSettings, driver_class

    cls = driver_class("azure_kinect")
    cfg = SensorConfig("hq", "hq", "azure_kinect", "001514394512", {"depth": StreamSettings("depth", "depth")},
                       options={"file": str(ak[0])})
    with cls(cfg) as drv:
        desc = drv.open()
        assert desc.streams["depth"].intrinsics.width == 640
        frames = list(drv.frames(timeout_s=1.0))
    assert [f.stream for f in frames] == ["depth"]
    assert isinstance(desc.T_depth_color, (Transform, type(None)))
