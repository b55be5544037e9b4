"""The session writer and reader: bit-exact round trip, schema, crash-safe publishing, --force."""
from __future__ import annotations

import json

import numpy as np
import pytest

from capture.session import SessionWriter, decode_depth, encode_depth, open_session
from data_manifests import schema_problem
from depthbench.errors import OutputExistsError
from tests.capture.sessionkit import manifest, tree_digest, write_source


def test_roundtrip_is_bit_exact_and_validates(tmp_path):
    root = tmp_path / "s"
    written = write_source(root, n=5, sensors=("lq", "hq"), streams=("depth", "color"), shift_us={"hq": -12_345})
    s = open_session(root, verify="full")
    assert schema_problem("session", json.loads((root / "session.json").read_text())) is None
    assert s.manifest["status"] == "complete"
    for (sensor, stream), rows in written.items():
        df = s.frames(sensor, stream)
        assert df["frame_number"].tolist() == [r[0] for r in rows]
        assert df["device_timestamp_us"].tolist() == [r[1] for r in rows]
        assert df["host_timestamp_us"].tolist() == [r[2] for r in rows]
        assert df["device_timestamp_us"].dtype == np.int64
        for fn, _, _, img in rows:
            back = s.read_image(sensor, stream, fn)
            assert back.dtype == img.dtype and back.shape == img.shape
            assert np.array_equal(back, img)
    # depth in metres: counts x unit, NaN exactly where the count is 0
    counts = written[("lq", "depth")][0][3]
    d = s.read_depth("lq", 0)
    assert d.dtype == np.float32
    assert np.array_equal(np.isnan(d), counts == 0)
    assert np.array_equal(d[counts > 0], counts[counts > 0].astype(np.float32) * np.float32(0.001))


def test_float_depth_roundtrip_and_ir(tmp_path):
    rng = np.random.default_rng(1)
    depth_m = rng.uniform(0.3, 8.0, (48, 64)).astype(np.float32)
    depth_m[::7, ::5] = np.nan
    ir = rng.integers(0, 65536, (48, 64), dtype=np.uint16)
    with SessionWriter(tmp_path / "s", manifest(("lq",), streams=("depth", "ir"))) as w:
        w.add_frame("lq", "depth", 3, 10, 20, depth_m)
        w.add_frame("lq", "ir", 3, 10, 20, ir)
    s = open_session(tmp_path / "s", verify="full")
    assert np.array_equal(s.read_depth("lq", 3), decode_depth(encode_depth(depth_m, 0.001), 0.001), equal_nan=True)
    assert np.nanmax(np.abs(s.read_depth("lq", 3) - depth_m)) <= 0.0005 + 1e-6
    assert np.array_equal(s.read_image("lq", "ir", 3), ir)


def test_writer_refuses_existing_output_without_force(tmp_path):
    root = tmp_path / "s"
    write_source(root, n=2)
    before = tree_digest(root)
    with pytest.raises(OutputExistsError, match="exists"):
        SessionWriter(root, manifest())
    with pytest.raises(OutputExistsError):
        SessionWriter(root, manifest(), staged=False)
    assert tree_digest(root) == before
    write_source(root, n=3, force=True)
    assert len(open_session(root).frames("lq", "depth")) == 3


def test_failed_staged_write_leaves_no_output_and_keeps_the_old_one(tmp_path):
    root = tmp_path / "s"
    write_source(root, n=2)
    before = tree_digest(root)
    with pytest.raises(RuntimeError):
        with SessionWriter(root, manifest(), force=True) as w:
            w.add_frame("lq", "depth", 0, 0, 0, np.zeros((48, 64), np.uint16))
            raise RuntimeError("boom")
    assert tree_digest(root) == before
    assert [p.name for p in tmp_path.iterdir()] == ["s"]  # no temporary folder left behind


def test_in_place_writer_publishes_a_readable_skeleton_at_once(tmp_path):
    w = SessionWriter(tmp_path / "s", manifest(("lq",)), staged=False)
    s = open_session(tmp_path / "s")  # readable before any frame, status "recording"
    assert s.manifest["status"] == "recording" and len(s.frames("lq")) == 0
    w.add_frame("lq", "depth", 0, 0, 0, np.ones((48, 64), np.uint16))
    assert len(open_session(tmp_path / "s", verify="full").frames("lq")) == 1
    w.close()
    assert open_session(tmp_path / "s").manifest["status"] == "complete"


def test_writer_refuses_out_of_order_and_wrong_frames(tmp_path):
    with SessionWriter(tmp_path / "s", manifest(("lq",))) as w:
        w.add_frame("lq", "depth", 5, 100, 100, np.ones((48, 64), np.uint16))
        for fn, dev, host in ((5, 200, 200), (4, 200, 200), (6, 99, 200), (6, 200, 99)):
            with pytest.raises(Exception, match="does not follow"):
                w.add_frame("lq", "depth", fn, dev, host, np.ones((48, 64), np.uint16))
        with pytest.raises(Exception, match="frame is 32x48"):
            w.add_frame("lq", "depth", 7, 300, 300, np.ones((48, 32), np.uint16))
        with pytest.raises(Exception, match="uint16 or float"):
            w.add_frame("lq", "depth", 7, 300, 300, np.ones((48, 64), np.uint8))
    assert open_session(tmp_path / "s", verify="full").frames("lq")["frame_number"].tolist() == [5]
