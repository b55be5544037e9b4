"""Lanes off vs on, keeping only the calls during which no other process used the CPU.

    PYTHONPATH=$PWD python quiet.py WIDTH LEVELS SECONDS [methods]

Each timed call records its wall time and the CPU jiffies of all other processes during it (/proc/stat busy
minus this process's utime+stime from /proc/self/stat); a call is "quiet" when the others used < 3 % of the two
cores over it. Modes alternate call by call, as in perf/ssdd_inference.py (whose helpers build the methods).
"""
import os, sys, time, tempfile
from pathlib import Path
import numpy as np, torch
sys.path.insert(0, "perf")
import ssdd_inference as P
from methods.base import FrameInput
from methods.tools.synthetic import synthetic_scene

HZ = os.sysconf("SC_CLK_TCK")
def busy():
    f = open("/proc/stat").readline().split()[1:]
    v = list(map(int, f))
    return v[0] + v[1] + v[2] + v[5] + v[6] + v[7]   # user nice system irq softirq steal
def mine():
    f = open("/proc/self/stat").read().rsplit(")", 1)[1].split()
    return int(f[11]) + int(f[12])
width, levels, seconds = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
names = sys.argv[4].split(",") if len(sys.argv) > 4 else ["ssdd_lstm", "ssdd_unet/4", "ssdd_unet"]
torch.set_num_threads(2)
_, depth = synthetic_scene((480, 640), seed=1)
frames = [FrameInput(0, depth), FrameInput(1, np.roll(depth, 3, axis=1))]
with tempfile.TemporaryDirectory() as tmp:
    path = P._weights(Path(tmp), width, levels, "bilateral", True)
    calls = {m: P._callables(*P._methods(path, m), depth, frames, 4) for m in ("off", "on")}
    for name in names:
        rec = {m: [] for m in calls}
        for m in calls:
            calls[m][name][0]()
        t_end = time.time() + seconds
        while time.time() < t_end:
            for m in calls:
                fn, n = calls[m][name]
                b0, s0, t0 = busy(), mine(), time.perf_counter()
                fn()
                dt = time.perf_counter() - t0
                others = (busy() - b0) - (mine() - s0)
                rec[m].append((dt * 1000 / n, others / HZ / (2 * dt)))
        q = {m: np.array([t for t, o in r if o < 0.03]) for m, r in rec.items()}
        a = {m: np.array([t for t, o in r]) for m, r in rec.items()}
        print(f"w{width}/{levels} {name:>11}: quiet calls off {len(q['off'])}/{len(a['off'])} on {len(q['on'])}/{len(a['on'])}; "
              f"quiet median off {np.median(q['off']) if len(q['off']) else np.nan:.1f} on {np.median(q['on']) if len(q['on']) else np.nan:.1f} "
              f"min off {a['off'].min():.1f} on {a['on'].min():.1f}; all median off {np.median(a['off']):.1f} on {np.median(a['on']):.1f} "
              f"(x off: quiet med {np.median(q['off']) / np.median(q['on']) if len(q['on']) and len(q['off']) else np.nan:.2f}, "
              f"min {a['off'].min() / a['on'].min():.2f}, all med {np.median(a['off']) / np.median(a['on']):.2f})", flush=True)
