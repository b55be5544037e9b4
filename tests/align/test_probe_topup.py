"""A view pair whose probes fall short of the feature minimum gets more probes from the rest of the session
instead of stopping the alignment (the demo's four-view rig had a pair at 57 of 60 matches with 8 probes); so does
a pair whose matches, enough in number, fit no pose."""
from __future__ import annotations

import json

import numpy as np

from align.pipeline import AlignOptions, ProbeBuilder, _spread, align_session, pair_setup
from capture.session import open_session
from tests.align.conftest import simulate_session


def test_a_pair_short_of_matches_takes_more_probes_and_the_rig_aligns(tmp_path):
    # seed 2001 (the demo's four-view rig), 0.6 s: with 5 probes view0 -> view3 holds 37 colour matches (< 60), the
    # other pairs 60-85; before, the alignment stopped with "only 37 colour feature matches ... (need 60)"
    root = simulate_session(tmp_path / "mv", rig="multiview4", seconds=0.6, seed=2001, scale=0.5)
    res = align_session(root, tmp_path / "a", probes=5, progress=False, workers=1, report=False)
    for v in ("view0", "view1", "view2", "view3"):
        assert (tmp_path / "a" / v / "aligned.json").exists()
    need = AlignOptions().min_matches
    for v, pf in res.views.items():
        matches = sum(p.n_features for p in pf.probes)
        assert matches >= need
        hq = [p.hq_index for p in pf.probes]
        assert hq == sorted(hq)
        # the first picks, exactly as without the top-up (independently: the same even spread over the candidates)
        setup = pair_setup(open_session(root), lq=pf.setup.lq, hq=pf.setup.hq)
        cand = ProbeBuilder(setup, AlignOptions(probes=5)).candidates()
        first = cand[np.unique(np.linspace(0, cand.size - 1, 5).round().astype(int))]
        assert set(first) <= set(hq)
        at_first = sum(p.n_features for p in pf.probes if p.hq_index in set(first))
        if v == "view3":
            assert at_first < need and len(hq) > 5      # short at first: topped up
        else:
            assert at_first >= need and len(hq) == 5    # enough at first: the probes asked for, no more
        meta = json.loads((tmp_path / "a" / v / "aligned.json").read_text())
        assert meta["alignment"]["probes"] == len(hq)


def test_spread_picks_evenly_with_both_ends():
    assert _spread(10, 4).tolist() == [0, 3, 6, 9]
    assert _spread(3, 5).tolist() == [0, 1, 2]
    assert _spread(0, 5).size == 0


def test_a_pair_whose_matches_fit_no_pose_takes_more_probes(tmp_path, caplog):
    # synchronous people session (seed 48; 11 before the simulated HQ integrated its footprints), 2 probes of at most
    # 60 SIFT features: the colour matches pass a minimum of 12, but the static ones give PnP no consistent pose;
    # before, fit_pair stopped there ("PnP found no consistent pose")
    from align.pipeline import fit_pair

    root = simulate_session(tmp_path / "s", time_shift_us=0, seed=48, seconds=2.0)
    setup = pair_setup(open_session(root), lq="lq", hq="hq")
    opts = AlignOptions(probes=2, max_features=60, min_matches=12, loop=False, progress=False, workers=1,
                        on_unobservable="flag")
    cand = ProbeBuilder(setup, opts).candidates()
    with caplog.at_level("INFO", logger="align.pipeline"):
        pf = fit_pair(setup, opts)
    assert "no consistent pose" in caplog.text and "more probe frames" in caplog.text
    hq = [p.hq_index for p in pf.probes]
    assert len(hq) > 2 and hq == sorted(hq) and {cand[0], cand[-1]} <= set(hq)
    assert pf.fit.n_inliers >= 12
