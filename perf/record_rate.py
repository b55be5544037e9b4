"""Recorder throughput: can ``depthbench capture record`` keep up with real time?

Plays a simulated ``lq-hq`` session (LQ 640x480 depth + colour, HQ 512x424 depth + 960x540
colour, all 30 fps, colour as PNG) through the replay driver, in real time, into a new session,
and reports:

1. the reference, in the same run: single-thread encode time of one frame set (what the writer
   must do 30 times a second), and the share of one core that real time needs;
2. the lq-hq rig at 30 fps for ``--seconds``: frames/s and MB/s written, writer drops, CPU used;
3. N simulated LQ sensors (depth + colour 640x480 at 30 fps each, N = 1, 2, ...): the highest N
   recorded without writer drops.

Usage::

    .venv/bin/python perf/record_rate.py [--source DIR] [--seconds 10] [--max-sensors 8]

``--source`` keeps (or reuses) the simulated source session; without it one is simulated into
a temporary folder (about 30 s). Output sessions go to a temporary folder and are deleted.
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from capture.drivers import SensorConfig  # noqa: E402
from capture.drivers.replay import ReplayDriver  # noqa: E402
from capture.recorder import default_writers, record  # noqa: E402
from capture.rig import Rig  # noqa: E402
from capture.session import encode_frame, open_session  # noqa: E402


def ensure_source(path: Path | None, seconds: float) -> Path:
    if path is not None and (path / "session.json").exists():
        return path
    from capture.sim.simulator import simulate

    target = path or Path(tempfile.mkdtemp(prefix="record-rate-src-")) / "sim-lq-hq"
    print(f"simulating lq-hq for {seconds:g} s into {target} ...", flush=True)
    simulate(target, rig="lq-hq", seconds=seconds, seed=3, color_encoding="png", progress=False, force=True)
    return target


def replay_sensor(sid: str, role: str, source: Path, serial: str) -> SensorConfig:
    return SensorConfig(sid, role, "replay", serial, {}, {}, {"session": str(source), "loop": True})


def warm_cache(source: Path, sensors=("lq", "hq")) -> None:
    """Decode the source once (the replay cache is shared), so recording runs measure the writer only."""
    for sid in sensors:
        drv = ReplayDriver(replay_sensor(sid, sid, source, sid))
        drv.open()
        drv.close()


def encode_reference(source: Path, *, fast: bool = False, reps: int = 5) -> tuple[float, int, dict]:
    """Single-thread encode time (s) and bytes of one frame set of every stream of the source."""
    s = open_session(source)
    total_t, total_b, per = 0.0, 0, {}
    for sid, sensor in s.sensors.items():
        for name, info in sensor.streams.items():
            df = s.frames(sid, name)
            img = s.read_image(sid, name, int(df["frame_number"].iloc[len(df) // 2]))
            t0 = time.perf_counter()
            for _ in range(reps):
                data, _ext = encode_frame(img, info, fast=fast)
            dt = (time.perf_counter() - t0) / reps
            per[f"{sid}/{name}"] = (dt, len(data), info.width, info.height)
            total_t += dt
            total_b += len(data)
    return total_t, total_b, per


def run_rig(rig: Rig, seconds: float, writers: int, adaptive: bool = True) -> dict:
    out = Path(tempfile.mkdtemp(prefix="record-rate-out-")) / "rec"
    cpu0 = time.process_time()
    try:
        r = record(rig, out, seconds=seconds, writers=writers, adaptive=adaptive)
        cpu = time.process_time() - cpu0
    finally:
        shutil.rmtree(out.parent, ignore_errors=True)
    expected = sum(len(c.streams or ()) for c in rig.sensors)
    due = r.wall_s * 30.0
    return {"frames_per_s": r.frames_per_s, "mb_per_s": r.mb_per_s, "writer_drops": r.writer_dropped,
            "drops": sum(s.dropped for s in r.streams.values()), "wall_s": r.wall_s, "cpu_cores": cpu / r.wall_s,
            "min_stream_ratio": min(s.frames / due for s in r.streams.values()), "streams": len(r.streams),
            "expected": expected, "fast_share": r.fast_encoded / max(r.frames, 1),
            "cpu_ms_per_frame": cpu / max(r.frames, 1) * 1e3}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--source", type=Path, default=None, help="simulated lq-hq session to replay (created if missing)")
    ap.add_argument("--source-seconds", type=float, default=2.0, help="length of a newly simulated source (s)")
    ap.add_argument("--seconds", type=float, default=10.0, help="recording length per run (s)")
    ap.add_argument("--max-sensors", type=int, default=8, help="largest number of LQ sensors to try")
    ap.add_argument("--writers", type=int, default=None, help=f"encoder threads (default {default_writers()})")
    args = ap.parse_args(argv)
    writers = args.writers or default_writers()
    source = ensure_source(args.source, args.source_seconds)
    print(f"cores: {os.cpu_count()}  load average before: {os.getloadavg()[0]:.2f}  encoder threads: {writers}  "
          f"source: {source}")
    warm_cache(source)

    print("\n1. reference: single-thread encode of one frame set (compressed PNG | uncompressed 'fast' PNG)")
    t_set, b_set, per = encode_reference(source)
    t_fast, b_fast, per_fast = encode_reference(source, fast=True)
    for k, (dt, nbytes, w, h) in per.items():
        print(f"   {k:<10} {w}x{h}  {dt * 1e3:6.1f} ms {nbytes / 1e6:5.2f} MB | {per_fast[k][0] * 1e3:5.1f} ms "
              f"{per_fast[k][1] / 1e6:5.2f} MB")
    print(f"   frame set  {t_set * 1e3:6.1f} ms {b_set / 1e6:5.2f} MB | {t_fast * 1e3:5.1f} ms {b_fast / 1e6:5.2f} MB"
          f"  -> 30 fps needs {t_set * 30:.2f} | {t_fast * 30:.2f} cores of encoding")

    lq_hq = Rig("record-rate-lq-hq", (replay_sensor("lq", "lq", source, "lq"), replay_sensor("hq", "hq", source, "hq")))
    for adaptive in (False, True):
        label = "adaptive (default)" if adaptive else "always compressed (--no-adaptive)"
        print(f"\n2{'b' if adaptive else 'a'}. lq-hq rig through the replay driver, 30 fps, {args.seconds:g} s, {label}")
        m = run_rig(lq_hq, args.seconds, writers, adaptive)
        print(f"   written {m['frames_per_s']:.1f} frames/s (real time: 120), {m['mb_per_s']:.1f} MB/s, writer drops "
              f"{m['writer_drops']}, all drops {m['drops']}, slowest stream at {m['min_stream_ratio'] * 100:.1f} % of "
              f"real time, CPU {m['cpu_cores']:.2f} cores ({m['cpu_ms_per_frame']:.1f} ms/frame: real time needs "
              f"{m['cpu_ms_per_frame'] * 120e-3:.2f} cores), {m['fast_share'] * 100:.0f} % of frames uncompressed")
        print(f"   -> {'keeps up' if m['writer_drops'] == 0 else 'DOES NOT keep up'} with real time")

    print("\n3. N simulated LQ sensors (640x480 depth + colour, 30 fps each)")
    best = 0
    for n in range(1, args.max_sensors + 1):
        rig = Rig(f"record-rate-{n}lq", tuple(replay_sensor(f"view{i}", "view", source, "lq") for i in range(n)))
        m = run_rig(rig, args.seconds, writers)
        ok = m["writer_drops"] == 0
        print(f"   N={n}: {m['frames_per_s']:6.1f} frames/s (real time: {60 * n}), {m['mb_per_s']:6.1f} MB/s, "
              f"writer drops {m['writer_drops']}, CPU {m['cpu_cores']:.2f} cores, {m['fast_share'] * 100:.0f} % "
              f"uncompressed {'ok' if ok else 'DROPS'}")
        if ok:
            best = n
        else:
            break
    print(f"   -> highest number of LQ sensors at 30 fps without writer drops: {best}")
    print(f"load average after: {os.getloadavg()[0]:.2f} (other processes take CPU from the recorder; numbers "
          f"are for this machine as loaded)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
