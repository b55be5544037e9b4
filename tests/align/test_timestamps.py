import numpy as np

from align.timestamps import regularize


def test_jitter_removed_and_gaps_honoured():
    rng = np.random.default_rng(0)
    f = np.arange(100, 1000)
    f = f[rng.random(f.size) > 0.05]  # dropped frames keep their numbers
    ideal = 1_700_000_000_000_000 + np.rint((f - 100) * 33333.4 * (1 + 25e-6)).astype(np.int64)
    raw = ideal + rng.integers(-1000, 1001, f.size)
    r = regularize(f, raw)
    assert r.method == "line"
    assert np.abs(r.stamps_us - ideal).max() < 120
    assert 500 < r.jitter_rms_us < 650


def test_wandering_clock_uses_a_local_line_and_garbage_stays_raw():
    f = np.arange(600)
    t = (f * 33333.3 + 5_000 * np.sin(f / 100)).astype(np.int64)  # the rate wanders by 0.15 %
    r = regularize(f, t + np.random.default_rng(1).integers(-500, 501, f.size))
    e = np.abs(r.stamps_us - t)
    assert r.method == "local" and np.median(e) < 150 and e.max() < 800  # one-sided windows at the ends
    bad = np.cumsum(np.random.default_rng(2).integers(1000, 200_000, 50))
    assert regularize(np.arange(50), bad).method == "raw"
    assert regularize(np.array([1, 1, 2]), np.array([0, 1, 2])).method == "raw"
