"""``depthbench capture info SESSION``: a table of sensors and streams."""
from __future__ import annotations

import numpy as np

from capture.session import open_session


def add_parser(sub) -> None:
    p = sub.add_parser("info", help="summarise a session: sensors, streams, frame counts, rates, drops",
                       description="Print one row per stream: sensor, role, model, resolution, frames, "
                                   "measured frame rate, dropped frames, depth unit.")
    p.add_argument("session", help="session folder")
    p.set_defaults(func=run)


def run(args) -> int:
    s = open_session(args.session)
    print(f"session '{s.name}'  time base: {s.time_base}  status: {s.manifest.get('status', 'complete')}")
    if s.effects:
        print("declared effects: " + ", ".join(f"{k}={v}" for k, v in s.effects.items()))
    header = f"{'sensor':<8} {'role':<5} {'model':<28} {'stream':<7} {'size':>9} {'frames':>7} {'fps':>6} {'dropped':>7} {'unit':>8}"
    print(header)
    print("-" * len(header))
    for sid, sensor in s.sensors.items():
        for name, st in sensor.streams.items():
            df = s.frames(sid, name)
            t = df[f"{s.time_base}_timestamp_us"].to_numpy()
            fps = (len(t) - 1) / ((t[-1] - t[0]) * 1e-6) if len(t) > 1 and t[-1] > t[0] else float("nan")
            dropped = s.manifest["sensors"][sid]["streams"][name].get("dropped_frames", "-")
            unit = f"{st.depth_unit_m * 1000:g}mm" if st.depth_unit_m else "-"
            print(f"{sid:<8} {sensor.role:<5} {sensor.model[:28]:<28} {name:<7} {st.width:>4}x{st.height:<4} "
                  f"{len(df):>7} {fps:>6.2f} {dropped!s:>7} {unit:>8}")
    return 0
