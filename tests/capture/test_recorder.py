"""The recorder with the replay driver as source: counts, images, rig errors, existing output, full disk, repair."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from capture.errors import RecordingError, RigError
from capture.recorder import StreamCounter, missing_between, record
from capture.repair import repair
from capture.rig import load_rig
from capture.session import open_session
from tests.capture.sessionkit import rig_toml, tree_digest, write_source
from tests.conftest import assert_one_line_error

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    root = tmp_path_factory.mktemp("rec") / "src"
    return root, write_source(root, n=40, sensors=("lq", "hq"))


# ----------------------------------------------------------------------------- counting rules (pure)
def test_missing_between_counter_gaps_and_long_intervals():
    p = 33_333.3
    assert missing_between(4, 0, 5, 33_333, p) == 0
    assert missing_between(4, 0, 7, 100_000, p) == 2  # counter gap
    assert missing_between(4, 0, 5, 100_000, p) == 2  # counter says nothing, the interval says 2 missing
    assert missing_between(4, 0, 5, 49_000, p) == 0   # under 1.5 periods: jitter, not a drop
    assert missing_between(4, 0, 5, 51_000, p) == 1   # over 1.5 periods


def test_stream_counter_classifies():
    c = StreamCounter(33_333.3)
    verdicts = [c.classify(n, d, h) for n, d, h in
                [(0, 0, 10), (1, 33_333, 20), (1, 33_333, 21), (3, 100_000, 30), (2, 66_666, 31), (4, 90_000, 40)]]
    assert verdicts == ["accept", "accept", "duplicate", "accept", "rejected", "rejected"]
    assert (c.stats.dropped, c.stats.duplicates, c.stats.rejected) == (1, 1, 2)


# ----------------------------------------------------------------------------- recording
def test_records_every_frame_bit_exact_and_reports_injected_drops_and_duplicates(source, tmp_path):
    src, written = source
    rig_path = tmp_path / "rig.toml"
    rig_path.write_text(rig_toml(src, {
        "lq": {"drop_frames": [3, 4, 17, 30], "duplicate_frames": [8, 9, 25]},
        "hq": {"drop_rate": 0.15, "duplicate_rate": 0.1, "seed": 5, "serial": "SER-hq"},
    }))
    result = record(load_rig(rig_path), tmp_path / "out", seconds=None)  # until the sources end
    assert result.stopped_by == "sources ended" and result.status == "complete"
    s = open_session(tmp_path / "out", verify="full")
    assert s.manifest["status"] == "complete" and s.manifest["source"]["host_clock"]["name"] == "CLOCK_MONOTONIC"
    from capture.drivers.replay import ReplayDriver  # what the rig's injections mean, computed independently
    for sid in ("lq", "hq"):
        cfg = load_rig(rig_path).sensor(sid)
        inj = ReplayDriver(cfg)
        inj.open()
        inj.close()
        for stream in ("depth", "color"):
            dropped = inj.injected[stream]["dropped_frames"]
            expect = [n for n in range(40) if n not in dropped]
            df = s.frames(sid, stream)
            assert df["frame_number"].tolist() == expect
            meta = s.manifest["sensors"][sid]["streams"][stream]
            inner = [n for n in dropped if 0 < n < 39 and n >= expect[0]]  # drops at the very end are invisible
            assert meta["dropped_frames"] == len(inner), (sid, stream, dropped)
            assert meta["duplicate_frames"] == inj.injected[stream]["duplicated"] > 0
            assert meta["writer_dropped_frames"] == 0
            assert result.streams[f"{sid}/{stream}"].dropped == len(inner)
            rows = {r[0]: r for r in written[("lq" if sid == "lq" else "hq", stream)]}
            for fn in expect[::7]:
                assert np.array_equal(s.read_image(sid, stream, fn), rows[fn][3])
            assert df["device_timestamp_us"].tolist() == [rows[n][1] for n in expect]
            assert np.all(np.diff(df["host_timestamp_us"].to_numpy()) > 0)
    assert s.manifest["sensors"]["lq"]["clock"]["domain"] == "replay"


def test_seconds_limit_and_progress_line(source, tmp_path):
    src, _ = source
    (tmp_path / "rig.toml").write_text(rig_toml(src, {"lq": {"loop": True}}))
    import io
    progress = io.StringIO()
    result = record(load_rig(tmp_path / "rig.toml"), tmp_path / "out", seconds=0.8, progress=progress,
                    progress_every_s=0.3)
    assert result.stopped_by == "time"
    assert 15 <= result.streams["lq/depth"].frames <= 30
    text = progress.getvalue()
    assert "lq/depth" in text and "fps" in text and "drop 0" in text and "MB/s" in text
    for bad in ({"seconds": 0}, {"seconds": 1, "buffer_s": 0}, {"seconds": 1, "writers": 0}):
        with pytest.raises(RecordingError):
            record(load_rig(tmp_path / "rig.toml"), tmp_path / "out2", **bad)
    assert not (tmp_path / "out2").exists()


def test_output_that_exists_is_never_touched(source, tmp_path, cli):
    src, _ = source
    (tmp_path / "rig.toml").write_text(rig_toml(src, {"lq": {}}))
    out = tmp_path / "out"
    out.mkdir()
    (out / "precious.txt").write_text("keep me")
    before = tree_digest(out)
    r = cli("capture", "record", "--rig", tmp_path / "rig.toml", "--out", out, "--seconds", "0.5")
    assert_one_line_error(r, str(out), "exists", "--force")
    assert tree_digest(out) == before
    r = cli("capture", "record", "--rig", tmp_path / "rig.toml", "--out", out, "--seconds", "0.3", "--force", "--quiet")
    assert r.returncode == 0, r.stderr
    assert not (out / "precious.txt").exists() and open_session(out).manifest["status"] == "complete"


BAD_RIGS = {
    "unknown_driver": ('[[sensor]]\nid = "lq"\nrole = "lq"\ndriver = "kinect9"\nserial = "1"\n', "unknown sensor driver 'kinect9'"),
    "missing_serial": ('[[sensor]]\nid = "lq"\nrole = "lq"\ndriver = "realsense"\n', "missing serial"),
    "empty_serial": ('[[sensor]]\nid = "lq"\nrole = "lq"\ndriver = "realsense"\nserial = " "\n', "missing serial"),
    "no_sensors": ('name = "x"\n', "no sensors"),
    "bad_role": ('[[sensor]]\nid = "lq"\nrole = "main"\ndriver = "realsense"\nserial = "1"\n', "role must be one of"),
    "bad_toml": ('[[sensor]\nid = "lq"\n', "not valid TOML"),
    "typo_key": ('[[sensor]]\nid = "lq"\nrole = "lq"\ndriver = "realsense"\nserial = "1"\nseriall = "2"\n', "unknown key 'seriall'"),
    "bad_fps": ('[[sensor]]\nid = "lq"\nrole = "lq"\ndriver = "realsense"\nserial = "1"\n[sensor.streams.depth]\nfps = -30\n',
                "fps must be a positive number"),
    "depth_as_jpeg": ('[[sensor]]\nid = "lq"\nrole = "lq"\ndriver = "realsense"\nserial = "1"\n'
                      '[sensor.streams.depth]\nencoding = "jpeg"\n', "does not fit a depth stream"),
    "duplicate_id": ('[[sensor]]\nid = "lq"\nrole = "lq"\ndriver = "replay"\nserial = "1"\n'
                     '[[sensor]]\nid = "lq"\nrole = "hq"\ndriver = "replay"\nserial = "2"\n', "used twice"),
    "replay_without_session": ('[[sensor]]\nid = "lq"\nrole = "lq"\ndriver = "replay"\nserial = "lq"\n', "options.session"),
    "bad_extrinsic": ('[[sensor]]\nid = "lq"\nrole = "lq"\ndriver = "replay"\nserial = "1"\n'
                      '[[extrinsics]]\ndst = "lq"\nsrc = "hq"\nT = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n', "src must name a sensor"),
}


@pytest.mark.parametrize("name", sorted(BAD_RIGS))
def test_bad_rig_files_are_refused_with_one_line(tmp_path, name):
    text, problem = BAD_RIGS[name]
    rig = tmp_path / f"{name}.toml"
    rig.write_text(text)
    with pytest.raises(RigError) as err:
        record(load_rig(rig), tmp_path / "out", seconds=1)
    message = str(err.value)
    assert "\n" not in message and str(rig) in message and problem in message, message
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("name", ["unknown_driver", "missing_serial", "replay_without_session"])
def test_bad_rig_files_through_the_cli(tmp_path, cli, name):
    text, problem = BAD_RIGS[name]
    rig = tmp_path / f"{name}.toml"
    rig.write_text(text)
    r = cli("capture", "record", "--rig", rig, "--out", tmp_path / "out", "--seconds", "1")
    assert_one_line_error(r, str(rig), problem)
    assert not (tmp_path / "out").exists()


def test_example_rig_files_are_valid():
    from capture.drivers import driver_class
    rigs = sorted((REPO / "data_manifests" / "rigs").glob("*.toml"))
    assert len(rigs) >= 3
    for path in rigs:
        rig = load_rig(path)
        for cfg in rig.sensors:
            if cfg.driver != "replay":
                driver_class(cfg.driver).check_config(cfg)
    assert load_rig(REPO / "data_manifests/rigs/lq-hq-realsense.toml").sensor("hq").sync == {"inter_cam_sync_mode": 2}


def test_missing_rig_file_and_missing_source(tmp_path, cli):
    r = cli("capture", "record", "--rig", tmp_path / "none.toml", "--out", tmp_path / "out")
    assert_one_line_error(r, str(tmp_path / "none.toml"), "not found")
    (tmp_path / "rig.toml").write_text(rig_toml(tmp_path / "no-such-session", {"lq": {}}))
    r = cli("capture", "record", "--rig", tmp_path / "rig.toml", "--out", tmp_path / "out")
    assert_one_line_error(r, "cannot replay", "no-such-session")
    assert not (tmp_path / "out").exists()


def test_sigterm_stops_cleanly(source, tmp_path):
    src, _ = source
    (tmp_path / "rig.toml").write_text(rig_toml(src, {"lq": {"loop": True}}))
    proc = subprocess.Popen([sys.executable, "-m", "depthbench", "capture", "record", "--rig", str(tmp_path / "rig.toml"),
                             "--out", str(tmp_path / "out"), "--quiet"], cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    _wait_for(tmp_path / "out" / "session.json", proc)
    import time
    time.sleep(0.5)
    proc.terminate()
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    s = open_session(tmp_path / "out", verify="full")
    assert s.manifest["status"] == "complete" and len(s.frames("lq", "depth")) > 5


def _wait_for(path: Path, proc, timeout=30.0):
    import time
    t0 = time.monotonic()
    while not path.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() - t0 < timeout
        time.sleep(0.02)


# ----------------------------------------------------------------------------- full disk
def _unshare_works() -> bool:
    if shutil.which("unshare") is None:
        return False
    probe = subprocess.run(["unshare", "--user", "--map-root-user", "--mount", "sh", "-c",
                            "d=$(mktemp -d) && mount -t tmpfs -o size=1m tmpfs $d && umount $d"], capture_output=True)
    return probe.returncode == 0


@pytest.mark.skipif(not _unshare_works(), reason="needs 'unshare' with user and mount namespaces to make a small tmpfs")
def test_full_disk_stops_cleanly_with_a_readable_session(tmp_path):
    src = tmp_path / "src"
    write_source(src, n=20, sensors=("lq",), w=320, h=240)  # ~0.4 MB per frame pair, incompressible
    (tmp_path / "rig.toml").write_text(rig_toml(src, {"lq": {"loop": True}}))
    mnt = tmp_path / "small"
    mnt.mkdir()
    script = textwrap.dedent(f"""
        mount -t tmpfs -o size=10m tmpfs {mnt} || exit 99
        {sys.executable} -m depthbench capture record --rig {tmp_path / 'rig.toml'} --out {mnt}/rec --seconds 20 --quiet --no-space-check
        echo "rc=$?" >&2
        {sys.executable} -c "
import json, sys
from capture.session import open_session
s = open_session('{mnt}/rec', verify='full')
print(json.dumps({{'status': s.manifest['status'], 'frames': len(s.frames('lq')),
                  'reserve': __import__('os').path.exists('{mnt}/rec/.recorder-reserve')}}))"
    """)
    proc = subprocess.run(["unshare", "--user", "--map-root-user", "--mount", "sh", "-c", script], cwd=REPO,
                          capture_output=True, text=True, timeout=120)
    err_lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert err_lines[-1] == "rc=2", proc.stderr
    assert len(err_lines) == 2 and "disk full" in err_lines[0] and "readable" in err_lines[0], proc.stderr
    assert "Traceback" not in proc.stderr
    info = json.loads(proc.stdout.strip().splitlines()[-1])
    assert info["status"] == "complete" and info["frames"] > 4 and not info["reserve"]


# ----------------------------------------------------------------------------- repair
def test_repair_fixes_what_a_crash_leaves(source, tmp_path, cli):
    src, _ = source
    (tmp_path / "rig.toml").write_text(rig_toml(src, {"lq": {"drop_frames": [6]}}))
    record(load_rig(tmp_path / "rig.toml"), tmp_path / "out")
    root = tmp_path / "out"
    # what a crash can leave: status recording, no checksums, temp files, unindexed frames, a partial row
    m = json.loads((root / "session.json").read_text())
    m["status"] = "recording"
    del m["checksums"]
    for st in m["sensors"]["lq"]["streams"].values():
        st.pop("dropped_frames")
    (root / "session.json").write_text(json.dumps(m))
    (root / ".session.json.abc.tmp").write_text("{")
    (root / ".recorder-reserve").write_bytes(b"\0" * 10)
    (root / "lq/depth/.00000099.png.tmp").write_bytes(b"\x89PNG partial")
    shutil.copy(root / "lq/depth/00000001.png", root / "lq/depth/00000099.png")
    table = root / "lq/frames.csv"
    lines = table.read_text().splitlines(keepends=True)
    victim = lines[5].split(",")  # a row whose frame file vanished (power loss before the data hit the disk)
    (root / victim[4]).unlink()
    table.write_text("".join(lines) + "depth,98,1,2,lq/depth/000")
    assert_one_line_error(cli("capture", "validate", root), "frames.csv", "expected 6 fields")
    assert repair(root, dry_run=True).changed and (root / ".recorder-reserve").exists()  # dry run changes nothing
    r = cli("capture", "repair", root, "-v")
    assert r.returncode == 0, r.stderr
    assert "missing" in r.stdout and "00000099.png" in r.stdout
    s = open_session(root, verify="full")
    assert s.manifest["status"] == "repaired"
    assert len(s.frames("lq")) == len(lines) - 2  # header and the row with the missing file
    assert s.manifest["sensors"]["lq"]["streams"]["depth"]["dropped_frames"] >= 1  # recomputed from the index
    left = {p.name for p in root.rglob("*") if p.is_file()}
    assert not {".session.json.abc.tmp", ".recorder-reserve", ".00000099.png.tmp", "00000099.png"} & left
    again = cli("capture", "repair", root)
    assert again.returncode == 0 and "nothing to repair" in again.stdout
    assert_one_line_error(cli("capture", "repair", tmp_path / "nope"), str(tmp_path / "nope"), "not a session folder")
