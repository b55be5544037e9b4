"""TUM RGB-D folders, built in tmp_path from the real Kinect v1 pair in shared/data/real/tum_kinect1_sample/."""
from __future__ import annotations

import json
import os

import cv2
import numpy as np
import pytest

from capture.drivers.tum import parse_timestamp_us
from capture.errors import SessionFormatError
from capture.session import open_session
from tests.capture.inproc_cli import run_inproc
from tests.conftest import assert_one_line_error

DEPTH_TS = ["1305031102.160407", "1305031102.194330", "1305031102.226738"]
RGB_TS = ["1305031102.175304", "1305031102.211214", "1305031102.243211"]


def _link(src, dst):
    try:
        os.symlink(src, dst)
    except OSError:  # filesystems without symlinks: a copy in tmp
        dst.write_bytes(src.read_bytes())


@pytest.fixture
def tum_folder(real_data, tmp_path):
    """A TUM-layout folder (lists with comments, rgb/ and depth/) pointing at the real sample."""
    sample = real_data / "tum_kinect1_sample"
    root = tmp_path / "rgbd_dataset_sample"
    (root / "rgb").mkdir(parents=True)
    (root / "depth").mkdir()
    for ts in DEPTH_TS:
        _link(sample / "TUM_depth.png", root / "depth" / f"{ts}.png")
    for ts in RGB_TS:
        _link(sample / "TUM_color.png", root / "rgb" / f"{ts}.png")
    head = "# {} maps\n# file: 'rgbd_dataset_sample.bag'\n# timestamp filename\n"
    (root / "depth.txt").write_text(head.format("depth") + "".join(f"{t} depth/{t}.png\n" for t in DEPTH_TS))
    (root / "rgb.txt").write_text(head.format("color") + "".join(f"{t} rgb/{t}.png\n" for t in RGB_TS))
    return root


def test_timestamps_parse_exactly_to_microseconds():
    assert parse_timestamp_us("1305031102.175304", where="x") == 1305031102175304
    assert parse_timestamp_us("1305031102.1753045", where="x") == 1305031102175304  # half to even
    assert parse_timestamp_us("1305031102.1", where="x") == 1305031102100000
    assert parse_timestamp_us("17", where="x") == 17_000_000
    with pytest.raises(SessionFormatError, match="not a number"):
        parse_timestamp_us("12:30", where="x")


def test_import_tum_folder(tum_folder, real_data, tmp_path, cli):
    out = tmp_path / "session"
    r = cli("capture", "import", "tum", tum_folder, "--out", out)
    assert r.returncode == 0, r.stderr
    s = open_session(out, verify="full")
    assert list(s.sensors) == ["lq"] and s.sensors["lq"].role == "lq"
    depth = s.frames("lq", "depth")
    assert depth["frame_number"].tolist() == [0, 1, 2]
    assert depth["device_timestamp_us"].tolist() == [int(t.replace(".", "")) for t in DEPTH_TS]
    assert depth["host_timestamp_us"].tolist() == depth["device_timestamp_us"].tolist()
    assert s.frames("lq", "color")["device_timestamp_us"].tolist() == [int(t.replace(".", "")) for t in RGB_TS]
    # depth / 5000 = metres, exactly the PNG's counts on disk
    raw = cv2.imread(str(real_data / "tum_kinect1_sample" / "TUM_depth.png"), cv2.IMREAD_UNCHANGED)
    assert s.stream("lq", "depth").depth_unit_m == pytest.approx(1 / 5000, rel=1e-15)
    assert np.array_equal(s.read_image("lq", "depth", 1), raw)
    m = s.read_depth("lq", 1)
    assert np.allclose(m[raw > 0], raw[raw > 0] / 5000.0, rtol=1e-6) and np.isnan(m[raw == 0]).all()
    assert np.nanmedian(m) == pytest.approx(2.415, abs=0.01)
    bgr = cv2.imread(str(real_data / "tum_kinect1_sample" / "TUM_color.png"), cv2.IMREAD_COLOR)
    assert np.array_equal(s.read_color("lq", 2), cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
    # TUM's default Kinect v1 intrinsics for both streams; depth registered to colour
    for stream in ("depth", "color"):
        K = s.intrinsics("lq", stream)
        assert (K.width, K.height, K.fx, K.fy, K.cx, K.cy) == (640, 480, 525.0, 525.0, 319.5, 239.5)
    assert s.sensors["lq"].T_depth_color.is_close(s.sensors["lq"].T_depth_color.identity())
    assert s.manifest["sensors"]["lq"]["technology"] == "structured_light"
    assert cli("capture", "validate", out).returncode == 0


def test_intrinsics_role_and_id_can_be_given(tum_folder, tmp_path, capfd):
    out = tmp_path / "fr1"
    r = run_inproc(capfd, "capture", "import", "tum", tum_folder, "--out", out, "--role", "hq", "--sensor-id", "kinect",
            "--intrinsics", "517.3,516.5,318.6,255.3,0.2624,-0.9531,-0.0054,0.0026,1.1633", "--no-color", "--quiet")
    assert r.returncode == 0, r.stderr
    s = open_session(out)
    K = s.intrinsics("kinect", "depth")
    assert (K.fx, K.fy, K.cx, K.cy) == (517.3, 516.5, 318.6, 255.3)
    assert K.coeffs == (0.2624, -0.9531, -0.0054, 0.0026, 1.1633)
    assert set(s.sensors["kinect"].streams) == {"depth"} and s.sensors["kinect"].role == "hq"


def test_missing_depth_list_is_one_line_error(tum_folder, tmp_path, capfd):
    (tum_folder / "depth.txt").unlink()
    r = run_inproc(capfd, "capture", "import", "tum", tum_folder, "--out", tmp_path / "s")
    assert_one_line_error(r, "depth.txt", "missing")


def test_empty_depth_list_means_no_depth_stream(tum_folder, tmp_path, capfd):
    (tum_folder / "depth.txt").write_text("# depth maps\n")
    r = run_inproc(capfd, "capture", "import", "tum", tum_folder, "--out", tmp_path / "s")
    assert_one_line_error(r, "depth.txt", "no depth")


def test_broken_png_is_one_line_error_and_nothing_is_written(tum_folder, tmp_path, cli):
    bad = tum_folder / "depth" / f"{DEPTH_TS[2]}.png"
    data = bad.read_bytes()
    bad.unlink()
    bad.write_bytes(data[: len(data) // 3])
    r = cli("capture", "import", "tum", tum_folder, "--out", tmp_path / "s")
    assert_one_line_error(r, DEPTH_TS[2])
    assert not (tmp_path / "s").exists() and not list(tmp_path.glob(".s.*"))


def test_listed_path_outside_the_folder_is_refused(tum_folder, tmp_path, capfd):
    (tum_folder / "rgb.txt").write_text(f"{RGB_TS[0]} ../../etc/passwd\n")
    r = run_inproc(capfd, "capture", "import", "tum", tum_folder, "--out", tmp_path / "s")
    assert_one_line_error(r, "rgb.txt", "escapes")


def test_existing_output_is_not_overwritten(tum_folder, tmp_path, capfd):
    out = tmp_path / "s"
    out.mkdir()
    (out / "notes.txt").write_text("keep")
    r = run_inproc(capfd, "capture", "import", "tum", tum_folder, "--out", out)
    assert_one_line_error(r, str(out), "--force")
    assert (out / "notes.txt").read_text() == "keep"
    assert run_inproc(capfd, "capture", "import", "tum", tum_folder, "--out", out, "--force", "--quiet").returncode == 0
    assert json.loads((out / "session.json").read_text())["source"]["importer"] == "tum"
