"""tidy2: the probe top-up case: a synchronous 2 s session (seed 11), probes=2, max_features=60, min_matches=12:
before the change fit_pair stopped on a FeatureError (PnP); usage: topup_case.py OUT_SESSION SECONDS (2.0)."""
import time, sys
from pathlib import Path
t = time.process_time()
from tests.align.conftest import simulate_session
root = simulate_session(Path(sys.argv[1]), time_shift_us=0, seed=11, seconds=float(sys.argv[2]))
print("sim cpu", time.process_time() - t)
from align.pipeline import AlignOptions, fit_pair, pair_setup
from capture.session import open_session
setup = pair_setup(open_session(root), lq="lq", hq="hq")
o = AlignOptions(probes=2, max_features=60, min_matches=12, loop=False, progress=False, workers=1, on_unobservable="flag")
t = time.process_time()
try:
    pf = fit_pair(setup, o); print("ok", len(pf.probes), pf.fit.n_pairs)
except Exception as e:
    print("ERR", type(e).__name__, e)
print("fit cpu", time.process_time() - t)
