"""align_session on a multiview session: python mv_align.py SESSION OUT PROBES"""
import sys, time
from align.pipeline import align_session
t = time.process_time()
try:
    r = align_session(sys.argv[1], sys.argv[2], force=True, probes=int(sys.argv[3]), progress=False, workers=1,
                      report=False, on_unobservable="flag")
    print({v: len(pf.probes) for v, pf in r.views.items()}, {v: sum(p.n_features for p in pf.probes) for v, pf in r.views.items()})
except Exception as e:
    print("FAILED:", type(e).__name__, e)
print(f"CPU {time.process_time() - t:.1f} s")
