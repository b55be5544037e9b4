import logging, sys, tempfile, io
from pathlib import Path
sys.path.insert(0, '/work/wt/footprint')
from align.pipeline import AlignOptions, ProbeBuilder, pair_setup, fit_pair
from capture.session import open_session
from tests.align.conftest import simulate_session
buf = io.StringIO()
h = logging.StreamHandler(buf); logging.getLogger('align.pipeline').addHandler(h); logging.getLogger('align.pipeline').setLevel(logging.INFO)
for seed in range(int(sys.argv[1]), int(sys.argv[2])):
    with tempfile.TemporaryDirectory() as d:
        buf.truncate(0); buf.seek(0)
        root = simulate_session(Path(d) / 's', time_shift_us=0, seed=seed, seconds=2.0)
        setup = pair_setup(open_session(root), lq='lq', hq='hq')
        opts = AlignOptions(probes=2, max_features=60, min_matches=12, loop=False, progress=False, workers=1, on_unobservable='flag')
        try:
            pf = fit_pair(setup, opts)
            ok = f"probes {len(pf.probes)} inliers {pf.fit.n_inliers}"
        except Exception as e:
            ok = f"ERR {e}"
        t = buf.getvalue()
        print(seed, 'no consistent pose' in t, 'more probe frames' in t, ok, flush=True)
