"""Colour matches per pair of a simulated multiview4 session at the first `probes` probes (no top-up):
python mv_counts.py OUT SEED SECONDS PROBES [SCALE]"""
import sys, time
from dataclasses import replace
from pathlib import Path
import numpy as np
from capture.sim import simulate
from capture.session import open_session
from align.pipeline import AlignOptions, ProbeBuilder, pair_setup, _spread, _run_probes

out, seed, seconds, probes = Path(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
scale = float(sys.argv[5]) if len(sys.argv) > 5 else 0.5
t = time.process_time()
if not out.exists():
    simulate(out, rig="multiview4", scene="people", seconds=seconds, seed=seed, scale=scale, progress=False, workers=1)
ts = time.process_time() - t
sess = open_session(out)
views = sess.sensors_with_role("view")
opts = AlignOptions(probes=probes, progress=False, workers=1)
for v in views:
    src = views[0] if v != views[0] else views[1]
    st = pair_setup(sess, lq=v, hq=src)
    b = ProbeBuilder(st, opts)
    cand = b.candidates()
    ps = _run_probes(b, cand[_spread(cand.size, probes)], opts, "f")
    allp = _run_probes(b, cand, opts, "f")
    print(f"seed {seed} {src}->{v}: {sum(p.n_features for p in ps)} matches over {len(ps)} probes; "
          f"{sum(p.n_features for p in allp)} over all {cand.size} candidates", flush=True)
print(f"sim CPU {ts:.1f} s, total CPU {time.process_time() - t:.1f} s")
