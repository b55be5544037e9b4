"""``depthbench capture record --seconds S`` refuses, before opening the output, a recording whose
frames could not fit the free disk space: one line, exit 2, nothing written."""
from __future__ import annotations

import os

import pytest

from capture.errors import DiskSpaceError
from capture.session import StreamInfo, check_disk_space, frame_bytes_bound, open_session
from depthbench import frames as codec
from tests.capture.inproc_cli import run_inproc
from tests.capture.sessionkit import rig_toml, tree_digest, write_source
from tests.conftest import assert_one_line_error


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    root = tmp_path_factory.mktemp("rec") / "src"
    write_source(root, n=8, sensors=("lq", "hq"))
    return root


def test_bound_is_the_largest_frame_the_writer_can_write(source):
    s = open_session(source)
    for sensor in ("lq", "hq"):
        for name, info in s.sensors[sensor].streams.items():
            biggest = max(len(codec.encode_png(s.read_image(sensor, name, i), params=codec.PNG_STORED))
                          for i in range(3))
            assert biggest < frame_bytes_bound(info) < biggest + 2048 + 200


def test_check_compares_with_the_free_space(tmp_path):
    from capture.camera import Intrinsics

    info = StreamInfo("depth", "depth", 640, 480, 30.0, "png16", Intrinsics(640, 480, 500, 500, 320, 240), 0.001)
    per_s = 30 * frame_bytes_bound(info)
    assert check_disk_space(tmp_path / "new" / "session", [info], 1) == per_s
    with pytest.raises(DiskSpaceError, match=r"new/session: 1e\+09 s of 1 streams can take up to .* free"):
        check_disk_space(tmp_path / "new" / "session", [info], 1e9)


def test_record_too_long_for_the_disk_is_refused(source, tmp_path, capfd):
    (tmp_path / "rig.toml").write_text(rig_toml(source, {"lq": {}, "hq": {}}))
    before = tree_digest(source)
    out = tmp_path / "out"
    r = run_inproc(capfd, "capture", "record", "--rig", tmp_path / "rig.toml", "--out", out, "--seconds", "1e9")
    assert_one_line_error(r, str(out), "1e+09 s of 4 streams", "free", "--no-space-check")
    assert not out.exists() and tree_digest(source) == before
    assert sorted(os.listdir(tmp_path)) == ["rig.toml"]
    # with the check off, the replay ends with its source (8 frames), long before 1e9 s
    r = run_inproc(capfd, "capture", "record", "--rig", tmp_path / "rig.toml", "--out", out, "--seconds", "1e9",
                   "--no-space-check", "--quiet")
    assert r.returncode == 0, r.stderr
    assert len(open_session(out).frames("lq", "depth")) == 8
