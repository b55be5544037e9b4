"""Timestamp association: eq. 28 against a loop, greedy against a direct copy of TUM's associate.py."""
import logging

import numpy as np
import pytest

from align.association import associate, associate_greedy, nearest_mapping, overlap_us
from align.errors import AssociationError


def tum_associate(first_list, second_list, offset, max_difference):
    """TUM RGB-D benchmark ``associate.py`` (Sturm et al.), re-typed from the original, Python 3."""
    first_keys = list(first_list.keys())
    second_keys = list(second_list.keys())
    potential_matches = [(abs(a - (b + offset)), a, b)
                         for a in first_keys
                         for b in second_keys
                         if abs(a - (b + offset)) < max_difference]
    potential_matches.sort()
    matches = []
    for diff, a, b in potential_matches:
        if a in first_keys and b in second_keys:
            first_keys.remove(a)
            second_keys.remove(b)
            matches.append((a, b))
    matches.sort()
    return matches


def loop_nearest(t_hq, t_lq, shift):
    out = []
    for t in t_hq:
        d = [abs(int(tl) - (int(t) + shift)) for tl in t_lq]
        out.append(int(np.argmin(d)))
    return np.array(out)


def _tum_pairs(t_hq, t_lq, shift, max_diff):
    m = tum_associate({int(a): None for a in t_lq}, {int(b): None for b in t_hq}, shift, max_diff)
    lq_pos = {int(a): i for i, a in enumerate(t_lq)}
    hq_pos = {int(b): i for i, b in enumerate(t_hq)}
    return [(hq_pos[b], lq_pos[a]) for a, b in m]


def test_nearest_matches_loop_random():
    rng = np.random.default_rng(1)
    for _ in range(20):
        t_hq = np.cumsum(rng.integers(20000, 45000, size=60)).astype(np.int64)
        t_lq = np.cumsum(rng.integers(25000, 40000, size=70)).astype(np.int64) + rng.integers(-50000, 50000)
        shift = int(rng.integers(-60000, 60000))
        np.testing.assert_array_equal(nearest_mapping(t_hq, t_lq, shift), loop_nearest(t_hq, t_lq, shift))


def test_nearest_tie_takes_earlier_frame_and_edges():
    t_lq = np.array([0, 100, 200], np.int64)
    assert nearest_mapping(np.array([-500, 50, 900], np.int64), t_lq).tolist() == [0, 0, 2]
    assert nearest_mapping(np.array([50], np.int64), t_lq, 50).tolist() == [1]


def test_greedy_corner_case_nearer_pair_already_taken():
    # HQ 9 and HQ 12 both look nearest to LQ 10. TUM takes (10, 9) first (diff 1); HQ 12 must then
    # fall back to LQ 20 (diff 8), although LQ 10 "looks" nearer to it. Eq. 28 would map both to 10.
    t_lq = np.array([0, 10, 20], np.int64)
    t_hq = np.array([9, 12], np.int64)
    hq, lq = associate_greedy(t_hq, t_lq, max_difference_us=15)
    assert list(zip(hq.tolist(), lq.tolist())) == _tum_pairs(t_hq, t_lq, 0, 15) == [(0, 1), (1, 2)]
    assert nearest_mapping(t_hq, t_lq).tolist() == [1, 1]
    # with a tighter window the fallback is out of reach: HQ 12 stays unmatched
    hq, lq = associate_greedy(t_hq, t_lq, max_difference_us=8)
    assert list(zip(hq.tolist(), lq.tolist())) == _tum_pairs(t_hq, t_lq, 0, 8) == [(0, 1)]


def test_greedy_equals_tum_on_random_lists_with_offsets_and_ties():
    rng = np.random.default_rng(7)
    for trial in range(40):
        n, m = rng.integers(5, 40, size=2)
        step = 1000 if trial % 2 else 33333
        t_hq = np.unique(rng.integers(0, step * 30, size=n)).astype(np.int64)
        t_lq = np.unique(rng.integers(0, step * 30, size=m)).astype(np.int64)
        if trial % 3 == 0:  # force exact ties in difference
            t_lq = np.unique(np.concatenate([t_lq, t_hq + 5, t_hq - 5]))
        shift = int(rng.integers(-3 * step, 3 * step))
        max_diff = int(rng.integers(step // 4, 3 * step))
        hq, lq = associate_greedy(t_hq, t_lq, time_shift_us=shift, max_difference_us=max_diff)
        assert list(zip(hq.tolist(), lq.tolist())) == _tum_pairs(t_hq, t_lq, shift, max_diff), trial


def test_associate_logs_counts_and_reports_dt(caplog):
    t_hq = np.arange(0, 1_000_000, 33_333, dtype=np.int64)
    t_lq = t_hq + 40_000 + 3_000
    with caplog.at_level(logging.INFO, logger="align.association"):
        a = associate(t_hq, t_lq, time_shift_us=40_000, method="greedy", max_difference_us=20_000,
                      hq_name="kinect/depth", lq_name="d415/depth")
    assert len(a) == t_hq.size and np.all(a.dt_us == 3_000)
    assert f"{t_hq.size} of {t_hq.size} HQ frames matched" in caplog.text


def test_associate_no_overlap_names_both_streams():
    t_hq = np.arange(0, 1_000_000, 33_333, dtype=np.int64)
    t_lq = t_hq + 10_000_000
    for method in ("nearest", "greedy"):
        with pytest.raises(AssociationError, match=r"kinect/depth / d415/depth: .*do not overlap"):
            associate(t_hq, t_lq, method=method, max_difference_us=20_000, hq_name="kinect/depth",
                      lq_name="d415/depth")
    assert overlap_us(t_hq, t_lq) == 0
    assert overlap_us(t_hq, t_lq, 10_000_000) > 0
