"""The compiled kernel's building blocks: the vectorisable exp and the window."""
import numpy as np

from methods._kernels import T_MAX, default_radius, disk_window, exp_neg


def test_exp_neg_is_float32_exact():
    t = np.linspace(0.0, T_MAX, 400_001, dtype=np.float32)
    ours = exp_neg(t)
    ref = np.exp(-t.astype(np.float64))
    rel = np.abs(ours - ref) / ref
    assert rel.max() < 1.2e-7   # below one float32 ulp (2^-23 = 1.19e-7)
    assert ours.dtype == np.float32


def test_disk_window_is_the_disk_and_eq7_exponent():
    dy, dx, s = disk_window(3, 1.5)
    pairs = set(zip(dy.tolist(), dx.tolist()))
    expect = {(j, i) for j in range(-3, 4) for i in range(-3, 4) if i * i + j * j <= 9}
    assert pairs == expect
    np.testing.assert_allclose(s, (dy ** 2 + dx ** 2) / (2 * 1.5 ** 2), rtol=1e-6)


def test_default_radius():
    assert default_radius(0.3) == 1
    assert default_radius(1.0) == 2
    assert default_radius(2.5) == 5
    assert default_radius(3.0) == 6
