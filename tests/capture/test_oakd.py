"""OAK-D through depthai v3 without a device: what the SDK lets a host do alone.

* no device: enumeration is empty, ``devices`` says so, opening / recording gives one-line errors;
* the device part of the pipeline refuses a host-only ``dai.Pipeline(False)`` clearly;
* the host record/replay nodes: synthetic depth (RAW16) and colour (RGB888i) ``ImgFrame`` messages
  recorded by ``RecordMessage`` and replayed by ``ReplayMessage`` into a host node come out of
  :func:`imgframe_to_frame` with sequence numbers, both clocks and every pixel intact;
* calibration conversion from a host-built ``dai.CalibrationHandler`` (scaling, distortion order,
  extrinsics in metres, refusal of terms we cannot represent).
"""
from __future__ import annotations

import datetime
import json
import time

import numpy as np
import pytest

from capture.drivers.base import SensorConfig, StreamSettings
from capture.drivers.oakd import (OakDDriver, build_pipeline, dai, imgframe_to_frame, intrinsics_from_calibration,
                                  timedelta_us, transform_from_calibration)
from capture.errors import CalibrationError, DeviceError, RigError
from tests.capture.inproc_cli import run_inproc
from tests.conftest import assert_one_line_error


def _config(**kw):
    base = dict(id="lq", role="lq", driver="oakd", serial="14442C10D13EABCE00",
                streams={"depth": StreamSettings("depth", "depth", 640, 400, 30),
                         "color": StreamSettings("color", "color", 640, 400, 30)})
    base.update(kw)
    return SensorConfig(**base)


# ----------------------------------------------------------------------------- no device
def test_no_device_enumerates_none_and_open_is_a_clear_error():
    assert OakDDriver.enumerate() == []
    drv = OakDDriver(_config())
    with pytest.raises(DeviceError) as exc:
        drv.open()
    assert "14442C10D13EABCE00" in str(exc.value) and "connected: none" in str(exc.value)
    assert "\n" not in str(exc.value)
    drv.close()
    assert drv.read(timeout_s=0.01) is None


def test_devices_command_says_none_found(cli, capfd):
    r = cli("capture", "devices")
    assert r.returncode == 0, r.stderr
    assert "realsense  no devices found" in r.stdout and "oakd       no devices found" in r.stdout
    assert "No RealSense or OAK device found." in r.stdout
    r = run_inproc(capfd, "capture", "devices", "--json", "--driver", "oakd")
    assert r.returncode == 0 and json.loads(r.stdout) == [{"driver": "oakd", "problem": None, "devices": []}]


def test_recording_a_rig_with_an_oakd_is_one_line_error(tmp_path, cli):
    rig = tmp_path / "oak.toml"
    rig.write_text('name = "oak"\n\n[[sensor]]\nid = "lq"\nrole = "lq"\ndriver = "oakd"\nserial = "14442C10D13EABCE00"\n'
                   '[sensor.streams.depth]\ntype = "depth"\nwidth = 640\nheight = 400\nfps = 30\n')
    out = tmp_path / "rec"
    r = cli("capture", "record", "--rig", rig, "--out", out, "--seconds", "1")
    assert_one_line_error(r, "14442C10D13EABCE00", "no OAK device")
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("kw,fragment", [
    (dict(streams={"ir": StreamSettings("ir", "ir")}), "'depth' and 'color'"),
    (dict(streams={"depth": StreamSettings("depth", "depth", 640, 400), "color": StreamSettings("color", "color", 1280, 720)}),
     "same size"),
    (dict(options={"laser": 1}), "unknown OAK-D option"),
    (dict(sync={"role": "boss"}), "master"),
])
def test_rig_settings_are_checked(kw, fragment):
    with pytest.raises(RigError, match=fragment):
        OakDDriver.check_config(_config(**kw))
    OakDDriver.check_config(_config(options={"preset": "ROBOTICS"}, sync={"role": "slave"}))


# ----------------------------------------------------------------------------- host-only pipeline
def test_device_nodes_refuse_a_host_only_pipeline():
    d = dai()
    with d.Pipeline(False) as p, pytest.raises(DeviceError, match="needs a device"):
        build_pipeline(p)


W, H = 96, 60


def _depth(i):
    return np.random.default_rng(i).integers(0, 12000, (H, W), dtype=np.uint16)


def _color(i):
    return np.random.default_rng(100 + i).integers(0, 256, (H, W, 3), dtype=np.uint8)


def test_record_and_replay_nodes_round_trip_through_the_frame_converter(tmp_path):
    d = dai()
    n = 6
    dev_us = [5_000_000 + i * 33_333 for i in range(n)]
    host_us = [123_000_000 + i * 33_334 for i in range(n)]

    class Source(d.node.ThreadedHostNode):
        def __init__(self):
            super().__init__()
            self.depth = self.createOutput()
            self.color = self.createOutput()

        def run(self):
            for i in range(n):
                for out, img, typ in ((self.depth, _depth(i), d.ImgFrame.Type.RAW16),
                                      (self.color, _color(i), d.ImgFrame.Type.RGB888i)):
                    f = d.ImgFrame()
                    f.setType(typ)
                    f.setWidth(W)
                    f.setHeight(H)
                    f.setData(img.reshape(-1).view(np.uint8))
                    f.setSequenceNum(40 + i)
                    f.setTimestampDevice(datetime.timedelta(microseconds=dev_us[i]))
                    f.setTimestamp(datetime.timedelta(microseconds=host_us[i]))
                    out.send(f)
                time.sleep(0.005)
            time.sleep(0.3)
            self.stopPipeline()

    files = {"depth": tmp_path / "depth.mcap", "color": tmp_path / "color.mcap"}
    with d.Pipeline(False) as p:
        src = p.create(Source)
        for name, out in (("depth", src.depth), ("color", src.color)):
            rec = p.create(d.node.RecordMessage)
            rec.setRecordFile(str(files[name]))
            out.link(rec.input)
        p.start()
        deadline = time.monotonic() + 20
        while p.isRunning() and time.monotonic() < deadline:
            time.sleep(0.02)
    assert all(f.stat().st_size > 0 for f in files.values())

    got: dict[str, list] = {"depth": [], "color": []}

    class Sink(d.node.ThreadedHostNode):
        def __init__(self, stream):
            super().__init__()
            self.stream = stream
            self.inp = self.createInput(blocking=True, queueSize=64)

        def run(self):
            while self.isRunning():
                try:
                    msg = self.inp.get()
                except Exception:  # the queue closes when the pipeline stops
                    return
                got[self.stream].append(imgframe_to_frame(msg, self.stream, host_timestamp_us=0))

    with d.Pipeline(False) as p:
        for name, path in files.items():
            rp = p.create(d.node.ReplayMessage)
            rp.setReplayFile(str(path))
            # looping: a replay that ends stops the whole pipeline, dropping what its sinks still hold
            rp.setLoop(True)
            sink = p.create(Sink, name)
            rp.out.link(sink.inp)
        p.start()
        deadline = time.monotonic() + 20
        while p.isRunning() and time.monotonic() < deadline and min(map(len, got.values())) < n:
            time.sleep(0.02)

    for name in ("depth", "color"):
        frames = got[name][:n]
        assert [f.frame_number for f in frames] == [40 + i for i in range(n)]
        assert [f.device_timestamp_us for f in frames] == dev_us
        assert [f.metadata["host_synced_timestamp_us"] for f in frames] == host_us
        assert all(f.clock_domain == "device" for f in frames)
        for i, f in enumerate(frames):
            expected = _depth(i) if name == "depth" else _color(i)
            assert f.image.dtype == expected.dtype and np.array_equal(f.image, expected)


def test_timedelta_to_microseconds_is_exact():
    assert timedelta_us(datetime.timedelta(days=2, seconds=3, microseconds=7)) == 172_803_000_007
    assert timedelta_us(datetime.timedelta(microseconds=-1)) == -1


# ----------------------------------------------------------------------------- calibration
@pytest.fixture
def calib():
    d = dai()
    c = d.CalibrationHandler()
    c.setCameraIntrinsics(d.CameraBoardSocket.CAM_A, [[1000.5, 0, 960.25], [0, 1001.25, 540.75], [0, 0, 1]], 1920, 1080)
    c.setDistortionCoefficients(d.CameraBoardSocket.CAM_A,
                                [0.125, -0.25, 0.001, 0.002, 0.0625, 0.01, 0.02, 0.03, 0, 0, 0, 0, 0, 0])
    c.setCameraExtrinsics(d.CameraBoardSocket.CAM_B, d.CameraBoardSocket.CAM_A, [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                          [3.75, 0.125, -0.25])  # centimetres, as depthai stores them
    return c


def test_intrinsics_from_the_device_calibration(calib):
    d = dai()
    K = intrinsics_from_calibration(calib, d.CameraBoardSocket.CAM_A, 1920, 1080)
    assert (K.width, K.height, K.fx, K.fy, K.cx, K.cy) == (1920, 1080, 1000.5, 1001.25, 960.25, 540.75)
    assert K.distortion_model == "opencv"
    assert K.coeffs == (0.125, -0.25, 0.001, 0.002, 0.0625, 0.01, 0.02, 0.03)  # OpenCV order, float32 decimals
    small = intrinsics_from_calibration(calib, d.CameraBoardSocket.CAM_A, 640, 360)
    ref = calib.getCameraIntrinsics(d.CameraBoardSocket.CAM_A, 640, 360)
    assert (small.fx, small.cx) == pytest.approx((ref[0][0], ref[0][2]), abs=1e-4)
    assert small.fx == pytest.approx(1000.5 / 3, abs=1e-4)


def test_extrinsics_are_converted_to_metres(calib):
    d = dai()
    T = transform_from_calibration(calib, d.CameraBoardSocket.CAM_B, d.CameraBoardSocket.CAM_A)
    assert np.allclose(T.t, [0.0375, 0.00125, -0.0025], atol=1e-9)


def test_unrepresentable_distortion_is_refused(calib):
    d = dai()
    calib.setDistortionCoefficients(d.CameraBoardSocket.CAM_A, [0.1, 0, 0, 0, 0, 0, 0, 0, 0.01, 0, 0, 0, 0, 0])
    with pytest.raises(CalibrationError, match="thin-prism"):
        intrinsics_from_calibration(calib, d.CameraBoardSocket.CAM_A, 640, 360)
