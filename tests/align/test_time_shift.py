"""Time-shift search on synthetic probes (pure functions; the simulator end-to-end tests are elsewhere).

A synthetic rig: 3D points (some static, some moving with smooth non-linear motion) seen by an HQ
camera (their 3D positions at HQ instants) and an LQ camera (their pixels at LQ instants, which
are stamped with the shift). The exact answer is known, nothing here uses the code under test
to make the data.
"""
import numpy as np
import pytest

from align.errors import ShiftRangeError, UnobservableError
from align.time_shift import Probe, ShiftLoss, estimate_time_shift, probe_window
from capture.camera import Intrinsics, Transform

K = Intrinsics(640, 480, 600.0, 600.0, 320.0, 240.0)
T_lq_hq = Transform.from_rotvec([0.004, -0.03, 0.002], [0.125, 0.01, -0.005])


def _world(n_static=300, n_moving=150, seed=0, static=False):
    rng = np.random.default_rng(seed)
    P0 = np.column_stack([rng.uniform(-1.5, 1.5, n_static + n_moving), rng.uniform(-1, 1, n_static + n_moving),
                          rng.uniform(2.0, 5.0, n_static + n_moving)])
    vel = np.zeros_like(P0)
    if not static:
        vel[n_static:] = rng.normal(0, 0.8, (n_moving, 3)) * [1, 0.5, 0.3]  # m/s, walking pace
    freq = rng.uniform(0.3, 1.0, P0.shape[0])

    def at(t_s):  # positions (in the HQ camera frame) at scene time t (s): smooth, not linear
        return P0 + vel * np.sin(2 * np.pi * freq * t_s)[:, None] / (2 * np.pi * freq)[:, None]
    return at


def _probes(shift_us, *, drift_ppm=0.0, seconds=4.0, fps_hq=30.0, fps_lq=30.0, noise_px=0.3, jitter_us=0,
            static=False, seed=0, n_probes=20, range_us=(-60000, 60000)):
    rng = np.random.default_rng(seed + 1)
    at = _world(seed=seed, static=static)
    t0 = 1_700_000_000_000_000
    # scene time s; HQ stamps t_hq = t0 + s; LQ stamps = t0 + s + shift + drift * s
    s_hq = np.arange(0, seconds, 1 / fps_hq) + 0.0041
    s_lq = np.arange(0, seconds, 1 / fps_lq) + 0.0193
    t_hq = (t0 + np.rint(s_hq * 1e6) + rng.integers(-jitter_us, jitter_us + 1, s_hq.size)).astype(np.int64)
    t_lq = (t0 + np.rint(s_lq * 1e6 + shift_us + drift_ppm * 1e-6 * s_lq * 1e6)
            + rng.integers(-jitter_us, jitter_us + 1, s_lq.size)).astype(np.int64)
    probes = []
    for i in np.linspace(10, s_hq.size - 10, n_probes).astype(int):
        win = probe_window(int(t_hq[i]), t_lq, range_us)
        if win.size < 2:
            continue
        X = at(s_hq[i])
        tracks = np.stack([K.project(T_lq_hq.apply(at(s_lq[j]))) for j in win])
        # matching noise: one offset per feature (HQ and LQ keypoints of one point disagree a little),
        # tracking noise: small, per frame (optical flow follows the LQ keypoint smoothly)
        tracks += rng.normal(0, noise_px, (1,) + tracks.shape[1:]) + rng.normal(0, 0.05, tracks.shape)
        probes.append(Probe(int(i), int(t_hq[i]), X, win, t_lq[win], tracks, win.size // 2))
    return probes, t_hq, t_lq


@pytest.mark.parametrize("shift_us", [-55_000, -16_538, 0, 7_777, 33_333, 55_000])
def test_recovers_shift_to_sub_millisecond_across_the_range(shift_us):
    probes, _, _ = _probes(shift_us, seed=abs(shift_us) % 97)
    est = estimate_time_shift(probes, K, t0_us=1_700_000_000_000_000, model_error_us=0.0)  # formula probes
    assert abs(est.time_shift_us - shift_us) < 300, (est.time_shift_us, shift_us)
    assert est.observable and est.std_us < 300
    dt, dr = est.T_init.error_to(T_lq_hq)
    assert dt < 0.002 and dr < 0.05


def test_nearest_pairing_loss_is_piecewise_constant_but_interpolated_loss_is_not():
    # eq. 28 pairs a frame for every Delta between two switching points: the loss cannot see a
    # shift inside a frame interval; the interpolated loss can
    probes, t_hq, t_lq = _probes(10_000, seed=3)
    loss = ShiftLoss(probes, T_lq_hq, K)
    nearest = []
    for d in (2_000, 5_000, 8_000):
        vals = []
        for p in probes:
            j = np.argmin(np.abs(p.t_lq_us - (p.t_hq_us + d)))
            vals.append(np.nanmean(np.linalg.norm(K.project(T_lq_hq.apply(p.points)) - p.tracks[j], axis=1)))
        nearest.append(np.mean(vals))
    interp = [loss(d) for d in (2_000, 5_000, 8_000)]
    assert np.ptp(nearest) < 1e-9 or len(set(np.round(nearest, 9))) <= 2
    assert interp[0] > interp[1] > interp[2]  # falls towards the true 10 ms inside the interval


def test_static_scene_is_unobservable():
    probes, _, _ = _probes(12_000, static=True, seed=5)
    with pytest.raises(UnobservableError, match="static"):
        estimate_time_shift(probes, K)


def test_shift_outside_the_range_is_refused():
    probes, _, _ = _probes(85_000, seed=6, range_us=(-60_000, 60_000))
    with pytest.raises(ShiftRangeError, match="edge of the search range"):
        estimate_time_shift(probes, K)


def test_jitter_averages_out_and_declared_facts_are_used():
    probes, _, _ = _probes(-23_000, seed=8, jitter_us=300)
    est = estimate_time_shift(probes, K)
    assert abs(est.time_shift_us + 23_000) < 500
    dec = estimate_time_shift(probes, K, declared_shift_us=-23_456)
    assert dec.model == "declared" and dec.time_shift_us == -23_456


def test_linear_drift_model():
    # 400 ppm over 8 s is 3.2 ms of drift: a constant model is off at the ends, the linear one is not
    probes, t_hq, _ = _probes(-20_000, drift_ppm=400.0, seconds=8.0, seed=9, n_probes=32)
    est = estimate_time_shift(probes, K, model="linear", t0_us=1_700_000_000_000_000)
    assert abs(est.drift_ppm - 400.0) < 60
    assert abs(est.time_shift_us + 20_000) < 400
    seg = est.segments
    assert len(seg) == 4 and seg[-1][1] - seg[0][1] > 1500  # the local estimates show the slope


def test_stated_deviation_counts_the_error_all_probes_share():
    """By default the stated deviation adds the session-wide error (``MODEL_ERROR_US``) in quadrature
    to the statistical one; the estimate itself does not change."""
    from align.time_shift import MODEL_ERROR_US

    probes, _, _ = _probes(12_345, seed=5)
    bare = estimate_time_shift(probes, K, t0_us=1_700_000_000_000_000, model_error_us=0.0)
    full = estimate_time_shift(probes, K, t0_us=1_700_000_000_000_000)
    assert full.time_shift_us == bare.time_shift_us
    assert full.std_us == pytest.approx(np.hypot(bare.std_us, MODEL_ERROR_US))
    assert MODEL_ERROR_US > 3 * bare.std_us  # on formula probes the statistical part is small
