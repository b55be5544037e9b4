"""SIGKILL the recorder at random moments: the raw folder reads back, no partial frame is indexed,
only frames in flight are lost, and repair leaves a valid session."""
from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from capture.drivers import SensorConfig
from capture.drivers.replay import ReplayDriver
from capture.repair import repair
from capture.session import open_session
from tests.capture.sessionkit import rig_toml, write_source

REPO = Path(__file__).resolve().parents[2]
FPS = 30.0
BUFFER_S = 0.5
KILLS = 6


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    root = tmp_path_factory.mktemp("crash") / "src"
    write_source(root, n=30, sensors=("lq", "hq"), w=80, h=60)
    return root


def _expected_numbers(src: Path, sid: str, options: dict, stream: str, n_loops: int = 8) -> list[int]:
    """Frame numbers the replay delivers (after injected drops, duplicates removed), over several loops."""
    drv = ReplayDriver(SensorConfig(sid, "lq", "replay", sid, {}, {}, {"session": str(src), **options}))
    drv.open()
    one = sorted(set(e.frame_number for e in drv._events if e.stream == stream))
    drv.close()
    return [n + k * 30 for k in range(n_loops) for n in one]


def test_sigkill_at_random_moments(source, tmp_path):
    rng = random.Random(1234)
    options = {"lq": {"loop": True, "drop_frames": [4, 11, 12], "duplicate_frames": [7, 20]},
               "hq": {"loop": True, "serial": "SER-hq", "duplicate_frames": [3]}}
    rig = tmp_path / "rig.toml"
    rig.write_text(rig_toml(source, options))
    expected = {(sid, st): _expected_numbers(source, sid, {k: v for k, v in o.items() if k != "serial"}, st)
                for sid, o in options.items() for st in ("depth", "color")}
    lost = []
    for attempt in range(KILLS):
        out = tmp_path / f"rec{attempt}"
        # the recorder's library entry (what `depthbench capture record` calls), without the CLI's imports
        code = ("import sys; from capture.recorder import record; from capture.rig import load_rig; "
                f"record(load_rig(sys.argv[1]), sys.argv[2], buffer_s={BUFFER_S})")
        proc = subprocess.Popen([sys.executable, "-c", code, str(rig), str(out)],
                                cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        t0 = time.monotonic()
        while not (out / "session.json").exists():
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() - t0 < 60
            time.sleep(0.005)
        time.sleep(rng.uniform(0.0, 0.3) if attempt == 0 else rng.uniform(0.8, 2.5))
        proc.send_signal(signal.SIGKILL)
        kill_us = time.monotonic_ns() // 1000  # the recorder's host clock is CLOCK_MONOTONIC too
        proc.wait()
        lost.append(check_raw_and_repair(out, expected, kill_us=kill_us))
    print(f"frames lost per stream at each kill: {lost}")


def check_raw_and_repair(out: Path, expected: dict, kill_us: int) -> dict:
    # 1. the raw folder, as the kill left it, opens and every indexed frame is whole (checksum, decode, size)
    raw = open_session(out, verify="full")
    assert raw.manifest["status"] == "recording"
    counts, lost = {}, {}
    for (sid, stream), numbers in expected.items():
        got = raw.frames(sid, stream)["frame_number"].tolist()
        # 2. nothing lost in the middle: what is indexed is exactly a prefix of what the source delivered
        assert got == numbers[:len(got)], (sid, stream, got[:20])
        counts[(sid, stream)] = len(got)
        # 3. at most the frames in flight are lost. The replay delivers a frame every period from the
        #    first one's host time; everything due before the kill that is not indexed was lost. In flight
        #    are at most: this stream's share of the write queue (BUFFER_S of frames), one frame per
        #    encoder thread, and one being read.
        if got:
            host = raw.frames(sid, stream)["host_timestamp_us"].to_numpy()
            delivered_by_kill = [n for n in numbers if n - numbers[0] <= (kill_us - host[0]) / (1e6 / FPS)]
            lost[f"{sid}/{stream}"] = len(delivered_by_kill) - len(got)
            assert lost[f"{sid}/{stream}"] <= BUFFER_S * FPS + 3 + 2, (sid, stream, len(got), len(delivered_by_kill))
    # 4. repair: removes leftovers, keeps every indexed frame, validates
    result = repair(out)
    assert result.changed and not result.rows_removed
    s = open_session(out, verify="full")
    assert s.manifest["status"] == "repaired"
    for key, n in counts.items():
        assert len(s.frames(*key)) == n
    leftovers = [p for p in out.rglob(".*") if p.is_file()]
    assert not leftovers, leftovers
    indexed = {f for sid in s.sensors for f in s.frames(sid)["file"]}
    on_disk = {str(p.relative_to(out)) for p in out.rglob("*.png")}
    assert on_disk == indexed
    m = json.loads((out / "session.json").read_text())
    assert set(m["checksums"]) == {"lq/frames.csv", "hq/frames.csv"}
    assert os.path.exists(out / "session.json")
    return lost
