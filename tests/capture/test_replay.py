"""The replay driver: real-time playback of a session, injected drops and duplicates, refusals."""
from __future__ import annotations

import numpy as np
import pytest

import capture.drivers.replay as replay_module
from capture.drivers import SensorConfig, StreamSettings, driver_class
from capture.drivers.replay import ReplayDriver
from capture.errors import DeviceError, RigError
from tests.capture.sessionkit import write_source


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    root = tmp_path_factory.mktemp("replay") / "src"
    frames = write_source(root, n=12, sensors=("lq", "hq"), shift_us={"hq": 10_000})
    return root, frames


def config(source, serial="lq", streams=None, **options) -> SensorConfig:
    return SensorConfig(id=serial, role="lq", driver="replay", serial=serial, streams=streams or {},
                        options={"session": str(source), **options})


def play(drv) -> list:
    out = []
    for f in drv.frames(timeout_s=0.5):
        out.append(f)
    return out


def test_registered_and_plays_in_real_time_with_source_numbers_and_images(source):
    root, written = source
    assert driver_class("replay") is ReplayDriver
    drv = ReplayDriver(config(root))
    desc = drv.open()
    assert set(desc.streams) == {"depth", "color"} and desc.serial == "SER-lq"
    assert desc.streams["depth"].depth_unit_m == 0.001 and desc.streams["depth"].fps == 30.0
    frames = play(drv)
    drv.close()
    depth = [f for f in frames if f.stream == "depth"]
    assert [f.frame_number for f in depth] == list(range(12))
    assert [f.device_timestamp_us for f in depth] == [r[1] for r in written[("lq", "depth")]]
    for f, r in zip(depth, written[("lq", "depth")]):
        assert np.array_equal(f.image, r[3]) and f.image.dtype == np.uint16
    color = [f for f in frames if f.stream == "color"]
    assert np.array_equal(color[3].image, written[("lq", "color")][3][3])
    # real time: frame k is delivered no earlier than its recorded time after the playback start, and
    # (on a machine that is not overloaded) soon after it
    host = np.array([f.host_timestamp_us for f in depth])
    due = drv._group.epoch_us + (np.array([r[2] for r in written[("lq", "depth")]]) - written[("lq", "depth")][0][2])
    late = host - due
    assert late.min() >= 0, late
    assert np.median(late) < 30_000, late
    assert (host[-1] - host[0]) * 1e-6 >= 11 / 30 - 0.03  # 11 periods of 33.3 ms


def test_speed_and_loop(source):
    root, _ = source
    drv = ReplayDriver(config(root, streams={"depth": StreamSettings("depth", "depth")}, speed=4.0, loop=True))
    drv.open()
    got = []
    while len(got) < 30:
        got += drv.read(timeout_s=0.5)
    drv.close()
    assert drv.read(timeout_s=0.1) is None  # closed: the source has ended
    numbers = [f.frame_number for f in got]
    assert numbers[:30] == list(range(30))  # the loop continues the counter
    dev = np.diff([f.device_timestamp_us for f in got])
    assert np.all(dev > 0) and np.allclose(dev, 33_333, atol=1)
    host = np.array([f.host_timestamp_us for f in got])
    assert (host[-1] - host[0]) * 1e-6 < 29 * 0.0333 / 2  # 4x real time


def test_injected_drops_and_duplicates(source):
    root, _ = source
    drv = ReplayDriver(config(root, drop_frames=[2, 3, 9], duplicate_frames=[5], speed=8.0))
    drv.open()
    frames = play(drv)
    depth = [f.frame_number for f in frames if f.stream == "depth"]
    assert depth == [0, 1, 4, 5, 5, 6, 7, 8, 10, 11]
    assert drv.injected["depth"]["dropped_frames"] == [2, 3, 9]
    assert drv.injected["color"]["duplicated"] == 1


def test_random_injection_is_reproducible(source):
    root, _ = source
    runs = []
    for _ in range(2):
        drv = ReplayDriver(config(root, drop_rate=0.3, duplicate_rate=0.2, seed=3, speed=8.0))
        drv.open()
        runs.append([(f.stream, f.frame_number) for f in play(drv)])
    assert runs[0] == runs[1] and len(runs[0]) != 24


def test_two_replays_of_one_source_keep_their_relative_timing(source):
    """Both replays share one start instant, so the frames are *due* exactly as recorded (HQ 10 ms
    after LQ). Actual arrival times also depend on the OS scheduler (a loaded 2-core CI machine can
    starve one thread): they are only required to be paced, not asserted to the millisecond."""
    root, _ = source
    lq, hq = ReplayDriver(config(root, "lq")), ReplayDriver(config(root, "hq"))
    lq.open(), hq.open()
    import threading
    out = {}
    threads = [threading.Thread(target=lambda d=d, k=k: out.__setitem__(k, play(d))) for k, d in (("lq", lq), ("hq", hq))]
    [t.start() for t in threads]
    [t.join() for t in threads]
    assert lq._group is hq._group  # one start instant for both
    epoch, t_min = replay_module._EPOCHS.epoch(lq._group, 0)
    due = {k: np.array([d._due_us(e, epoch, t_min) for e in d._events if e.stream == "depth"]) for k, d in (("lq", lq), ("hq", hq))}
    assert np.median(due["hq"] - due["lq"]) == 10_000  # the source has hq 10 ms after lq
    for k in ("lq", "hq"):
        t = np.array([f.host_timestamp_us for f in out[k] if f.stream == "depth"])
        assert len(t) == len(due[k]) and np.all(np.diff(t) >= 0)
        assert np.all(t >= due[k])  # never emitted before it is due


@pytest.mark.parametrize("kwargs, streams, match", [
    ({"serial": "nope"}, None, "no sensor with id or serial 'nope'"),
    ({}, {"ir": StreamSettings("ir", "ir")}, "has no stream 'ir'"),
    ({}, {"depth": StreamSettings("depth", "depth", 640, 480)}, "cannot deliver 640x480"),
    ({}, {"depth": StreamSettings("depth", "depth", fps=60.0)}, "cannot deliver 60"),
])
def test_refuses_what_the_source_cannot_do(source, kwargs, streams, match):
    root, _ = source
    drv = ReplayDriver(config(root, kwargs.get("serial", "lq"), streams))
    with pytest.raises(DeviceError, match=match):
        drv.open()


def test_bad_options_and_missing_source(tmp_path):
    with pytest.raises(RigError, match="unknown option 'sped'"):
        ReplayDriver.check_config(config(tmp_path, sped=2))
    with pytest.raises(RigError, match="options.session"):
        ReplayDriver.check_config(SensorConfig("lq", "lq", "replay", "lq", {}, {}, {}))
    with pytest.raises(RigError, match="drop_frames"):
        ReplayDriver.check_config(config(tmp_path, drop_frames="5"))
    with pytest.raises(DeviceError, match="cannot replay"):
        ReplayDriver(config(tmp_path / "none")).open()


# ----------------------------------------------------------------------------- the driver interface and registry
def test_registry_lists_drivers_and_refuses_unknown_ones():
    from capture.drivers import Driver, enumerate_devices, known_drivers, register
    from capture.drivers.base import _REGISTRY

    assert {"realsense", "oakd", "replay"} <= set(known_drivers())
    with pytest.raises(RigError, match="unknown sensor driver 'nope'.*known: .*replay"):
        driver_class("nope")

    class Broken(Driver):
        name = "broken_for_test"

        @classmethod
        def enumerate(cls):
            raise RuntimeError("SDK exploded\nsecond line")

        def open(self):
            raise NotImplementedError

        def read(self, *, timeout_s):
            return None

        def close(self):
            pass

    register(Broken)
    try:
        listing = {li.driver: li for li in enumerate_devices(["replay", "broken_for_test"])}
        assert listing["replay"].devices == [] and listing["replay"].problem is None
        assert listing["broken_for_test"].problem == "RuntimeError: SDK exploded"
    finally:
        _REGISTRY.pop("broken_for_test")


def test_descriptions_check_themselves_and_write_manifest_entries():
    from capture.camera import Intrinsics
    from capture.drivers import SensorDescription, StreamDescription

    K = Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5)
    with pytest.raises(DeviceError, match="positive depth_unit_m"):
        StreamDescription("depth", "depth", 64, 48, 30.0, "png16", K)
    with pytest.raises(DeviceError, match="unknown encoding"):
        StreamDescription("color", "color", 64, 48, 30.0, "webp", K)
    d = SensorDescription("m", "s1", {"depth": StreamDescription("depth", "depth", 64, 48, 30.0, "png16", K, 0.001)},
                          firmware="1.2", technology="stereo", clock={"domain": "hardware_clock"})
    entry = d.to_manifest("lq")
    assert entry["streams"]["depth"]["depth_unit_m"] == 0.001 and entry["firmware"] == "1.2"
    from data_manifests import schema_problem
    m = {"format": "depthbench.session", "format_version": "1.0", "name": "x", "time_base": "host",
         "sensors": {"lq": {**entry, "frames": "lq/frames.csv"}}}
    assert schema_problem("session", m) is None
