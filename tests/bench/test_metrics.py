"""bench.metrics against brute-force references written here (per-pixel / per-point loops, exact neighbours)."""
from __future__ import annotations

import numpy as np
import pytest

from bench import metrics as M
from capture.camera import Intrinsics

K_SMALL = Intrinsics(80, 60, 70.0, 70.0, 39.5, 29.5)       # wide pixels: big radii exercise deep rings
K_NARROW = Intrinsics(80, 60, 500.0, 500.0, 39.5, 29.5)    # ~2 mm pixels at 1 m: realistic 5 mm neighbourhoods


def surface(K, base=0.5, bump=0.02, slant=(0.003, 0.0015)):
    v, u = np.mgrid[0:K.height, 0:K.width]
    z = base + slant[0] * u + slant[1] * v + bump * np.sin(u / 6.0) * np.cos(v / 5.0)
    return z.astype(np.float32)


def noisy_pair(K, *, seed=0, holes=0.05, lq_noise=0.004, hq_noise=0.0005, **kw):
    rng = np.random.default_rng(seed)
    t = surface(K, **kw)
    ref = (t + rng.normal(0, hq_noise, t.shape)).astype(np.float32)
    pred = (t + rng.normal(0, lq_noise, t.shape)).astype(np.float32)
    ref[rng.random(t.shape) < holes] = np.nan
    pred[rng.random(t.shape) < holes] = np.nan
    ref[10:16, 20:35] = np.nan           # a big hole in the reference
    pred[40:44, :] = np.nan              # a band the method left empty
    roi = np.zeros(t.shape, bool)
    roi[3:-3, 4:-6] = True
    return pred, ref, roi


# ------------------------------------------------------------------------------- brute force
def brute_pixels(pred, ref, roi):
    n = 0
    s_abs = s_sq = s = 0.0
    n_ref = 0
    for v in range(ref.shape[0]):
        for u in range(ref.shape[1]):
            r, p = float(ref[v, u]), float(pred[v, u])
            if roi is not None and not roi[v, u]:
                continue
            if not (np.isfinite(r) and r > 0):
                continue
            n_ref += 1
            if not (np.isfinite(p) and p > 0):
                continue
            e = (p - r) * 1000.0
            n += 1
            s += e
            s_abs += abs(e)
            s_sq += e * e
    return {"mse_mm2": s_sq / n, "rmse_mm": (s_sq / n) ** 0.5, "mae_mm": s_abs / n, "bias_mm": s / n,
            "n_valid": n, "fill_rate": n / n_ref}


def cloud(depth, K, mask):
    pts = {}
    for v in range(K.height):
        for u in range(K.width):
            if mask[v, u]:
                z = float(depth[v, u])
                pts[(v, u)] = np.array([(u - K.cx) / K.fx * z, (v - K.cy) / K.fy * z, z])
    return pts


def brute_plane_fit(pred, ref, K, roi, *, r, min_neighbors=3, ratio=0.1):
    """Per reference point: exact neighbours by scanning all points, np.linalg.eigh, closest point by scanning."""
    ok = lambda d: np.isfinite(d) & (d > 0)  # noqa: E731
    roi = np.ones(ref.shape, bool) if roi is None else roi
    rc = cloud(ref, K, ok(ref) & roi)
    qc = cloud(pred, K, ok(pred) & roi)
    R = np.array(list(rc.values()))
    Q = np.array(list(qc.values()))
    out = {}
    for (v, u), p in rc.items():
        if not ok(pred[v, u]):
            continue
        nb = R[np.sum((R - p) ** 2, axis=1) <= r * r]
        if len(nb) < min_neighbors:
            out[(v, u)] = ("few", len(nb), np.nan)
            continue
        c = nb.mean(axis=0)
        w, vec = np.linalg.eigh((nb - c).T @ (nb - c) / len(nb))
        if not w[1] > ratio ** 2 * w[2]:
            out[(v, u)] = ("degenerate", len(nb), np.nan)
            continue
        q = Q[np.argmin(np.sum((Q - p) ** 2, axis=1))]
        out[(v, u)] = ("ok", len(nb), abs(vec[:, 0] @ (q - c)))
    return out


def brute_normals(depth, K):
    H, W = depth.shape
    n = np.full((H, W, 3), np.nan)
    ok = np.isfinite(depth) & (depth > 0)
    for v in range(1, H - 1):
        for u in range(1, W - 1):
            if not (ok[v, u] and ok[v, u - 1] and ok[v, u + 1] and ok[v - 1, u] and ok[v + 1, u]):
                continue
            P = lambda vv, uu: np.array([(uu - K.cx) / K.fx, (vv - K.cy) / K.fy, 1.0]) * float(depth[vv, uu])  # noqa: E731
            c = np.cross(P(v, u + 1) - P(v, u - 1), P(v + 1, u) - P(v - 1, u))
            c /= np.linalg.norm(c)
            n[v, u] = -c if c[2] > 0 else c
    return n


# ------------------------------------------------------------------------------- pixel metrics
def test_pixel_metrics_match_brute_force():
    pred, ref, roi = noisy_pair(K_SMALL)
    for r in (roi, None):
        got = M.pixel_errors(pred, ref, r)
        want = brute_pixels(pred, ref, r)
        for k in ("mse_mm2", "rmse_mm", "mae_mm", "bias_mm"):
            assert got[k] == pytest.approx(want[k], rel=1e-9), k
        assert got["n_valid"] == want["n_valid"]
        assert M.fill_rate(pred, ref, r) == pytest.approx(want["fill_rate"], rel=1e-12)
        assert M.mse_mm2(pred, ref, r) == pytest.approx(want["mse_mm2"], rel=1e-9)
        assert M.rmse_mm(pred, ref, r) == pytest.approx(want["rmse_mm"], rel=1e-9)
        assert M.mae_mm(pred, ref, r) == pytest.approx(want["mae_mm"], rel=1e-9)


def test_identical_maps_have_zero_error_and_full_fill():
    _, ref, roi = noisy_pair(K_SMALL)
    e = M.pixel_errors(ref.copy(), ref, roi)
    assert e["mse_mm2"] == 0.0 and e["rmse_mm"] == 0.0 and e["mae_mm"] == 0.0
    assert M.fill_rate(ref.copy(), ref, roi) == 1.0
    # the plane fit of the reference against itself is not 0 but its own roughness about the local planes
    floor = M.plane_fit_rmse(ref.copy(), ref, K_SMALL, roi=roi, radius_m=0.03).rmse_mm
    assert 0.2 < floor < 1.5        # hq_noise 0.5 mm, plus the surface's curvature within 30 mm


def test_shift_by_5mm_raises_mae_by_5mm():
    rng = np.random.default_rng(3)
    _, ref, roi = noisy_pair(K_SMALL)
    assert M.mae_mm(ref + np.float32(0.005), ref, roi) == pytest.approx(5.0, abs=1e-3)   # float32 depth: ~0.1 um
    # a map whose errors are all >= 0: a +5 mm shift adds exactly 5 mm to every absolute error
    pred = ref.astype(np.float64) + np.abs(rng.normal(0, 0.003, ref.shape))
    before, after = M.mae_mm(pred, ref, roi), M.mae_mm(pred + 0.005, ref, roi)
    assert after - before == pytest.approx(5.0, abs=1e-9)
    assert M.pixel_errors(pred + 0.005, ref, roi)["bias_mm"] - M.pixel_errors(pred, ref, roi)["bias_mm"] == \
        pytest.approx(5.0, abs=1e-9)


def test_fill_rate_counts_deleted_pixels():
    _, ref, roi = noisy_pair(K_SMALL)
    pred = ref.copy()
    R = M.reference_mask(ref, roi)
    kill = np.flatnonzero(R)[::4]
    pred.ravel()[kill] = np.nan
    assert M.fill_rate(pred, ref, roi) == pytest.approx(1 - len(kill) / R.sum())


def test_mismatched_shapes_are_refused():
    with pytest.raises(M.MetricInputError, match="same size"):
        M.pixel_errors(np.zeros((4, 5), np.float32), np.zeros((5, 4), np.float32))
    with pytest.raises(M.MetricInputError, match="radius"):
        M.MetricConfig(radius_m=0)


# ------------------------------------------------------------------------------- normals
def test_normal_map_and_angle_match_brute_force():
    pred, ref, roi = noisy_pair(K_SMALL, lq_noise=0.002)
    for depth in (pred, ref):
        got, want = M.normal_map(depth, K_SMALL), brute_normals(depth, K_SMALL)
        assert np.array_equal(np.isfinite(got), np.isfinite(want))
        np.testing.assert_allclose(got[np.isfinite(got)], want[np.isfinite(want)], rtol=1e-9, atol=1e-12)
    a, b = brute_normals(pred, K_SMALL), brute_normals(ref, K_SMALL)
    angles = []
    m = M.valid_mask(pred, ref, roi)
    for v, u in zip(*np.nonzero(m)):
        if np.isfinite(a[v, u]).all() and np.isfinite(b[v, u]).all():
            angles.append(np.degrees(np.arccos(np.clip(a[v, u] @ b[v, u], -1, 1))))
    assert M.normal_angle_deg(pred, ref, K_SMALL, roi) == pytest.approx(np.mean(angles), rel=1e-9)


# ------------------------------------------------------------------------------- eigen solver
def test_closed_form_eigen_solver_matches_lapack():
    rng = np.random.default_rng(7)
    A = rng.normal(size=(2000, 3, 3)) * rng.uniform(1e-4, 1e-2, size=(2000, 1, 1))
    C = A @ A.transpose(0, 2, 1)
    C[:500, :, 2] *= 1e-3                    # plane-like: one small eigenvalue
    C[:500, 2, :] *= 1e-3
    lo, mid, hi, v = M.smallest_eigh3(C[:, 0, 0], C[:, 0, 1], C[:, 0, 2], C[:, 1, 1], C[:, 1, 2], C[:, 2, 2])
    w, V = np.linalg.eigh(C)
    scale = w[:, 2]
    np.testing.assert_allclose(lo / scale, w[:, 0] / scale, atol=1e-10)
    np.testing.assert_allclose(mid / scale, w[:, 1] / scale, atol=1e-10)
    np.testing.assert_allclose(hi / scale, w[:, 2] / scale, atol=1e-10)
    gap = (w[:, 1] - w[:, 0]) / scale
    good = gap > 1e-3
    dots = np.abs(np.einsum("ij,ij->i", v, V[:, :, 0]))
    np.testing.assert_allclose(dots[good], 1.0, atol=1e-8)


# ------------------------------------------------------------------------------- plane fit
def _compare(pred, ref, K, roi, r, **kw):
    bf = brute_plane_fit(pred, ref, K, roi, r=r, **kw)
    d = np.array([x[2] for x in bf.values() if x[0] == "ok"])
    want = float(np.sqrt(np.mean(d ** 2)) * 1000) if d.size else float("nan")
    for method in ("grid", "kdtree"):
        res = M.plane_fit_rmse(pred, ref, K, roi=roi, radius_m=r, method=method,
                               min_neighbors=kw.get("min_neighbors", 3), min_spread_ratio=kw.get("ratio", 0.1))
        assert res.n_used == len(d), method
        assert res.n_excluded_few == sum(x[0] == "few" for x in bf.values()), method
        assert res.n_excluded_degenerate == sum(x[0] == "degenerate" for x in bf.values()), method
        if d.size:
            assert res.rmse_mm == pytest.approx(want, rel=1e-6), method
            for (v, u), (st, n, dist) in bf.items():
                assert res.neighbors[v, u] == n
                if st == "ok":
                    assert res.distance_m[v, u] == pytest.approx(dist, rel=1e-6, abs=1e-12)
    return want, bf


@pytest.mark.parametrize("r", [0.006, 0.012, 0.03])
def test_plane_fit_matches_brute_force(r):
    pred, ref, roi = noisy_pair(K_SMALL)
    want, bf = _compare(pred, ref, K_SMALL, roi, r)
    statuses = {x[0] for x in bf.values()}
    if r == 0.012:     # this radius mixes all three outcomes
        assert statuses == {"ok", "few", "degenerate"}
    if r == 0.03:      # windows of 3+ pixels: the deep rings of the grid search are used
        assert max(x[1] for x in bf.values()) > 25


def test_plane_fit_full_frame_without_holes_matches_brute_force():
    rng = np.random.default_rng(4)
    ref = surface(K_SMALL)
    pred = (ref + rng.normal(0, 0.004, ref.shape)).astype(np.float32)
    ref = (ref + rng.normal(0, 0.0005, ref.shape)).astype(np.float32)
    _compare(pred, ref, K_SMALL, None, 0.03)


def test_plane_fit_close_points_use_the_kdtree_fallback_and_still_match():
    pred, ref, roi = noisy_pair(K_SMALL, base=0.25, bump=0.005, slant=(0.0005, 0.0003))
    # a 60 mm ball at 0.25 m spans ~20 pixels: beyond the grid's window cap
    _compare(pred, ref, K_SMALL, roi, 0.06)


def test_plane_fit_sparse_prediction_needs_wide_closest_point_search():
    pred, ref, roi = noisy_pair(K_SMALL, lq_noise=0.001)
    sparse = np.full_like(pred, np.nan)
    sparse[::13, ::17] = pred[::13, ::17]          # the closest denoised point is many pixels away
    _compare(sparse, ref, K_SMALL, None, 0.012)


def test_plane_fit_without_roi_and_with_realistic_pixels():
    pred, ref, _ = noisy_pair(K_NARROW, base=1.0, bump=0.01, slant=(0.0004, 0.0002), lq_noise=0.003,
                              hq_noise=0.0005)
    _compare(pred, ref, K_NARROW, None, 0.005)


def test_plane_fit_with_millimetre_quantised_depth_breaks_ties_the_same_way():
    # depth in whole millimetres (like the DDRNet PNGs): many closest points tie exactly
    pred, ref, roi = noisy_pair(K_NARROW, base=1.0, bump=0.01, slant=(0.0004, 0.0002), lq_noise=0.002)
    pred, ref = np.round(pred * 1000) / 1000, np.round(ref * 1000) / 1000
    pred, ref = pred.astype(np.float32), ref.astype(np.float32)
    _compare(pred, ref, K_NARROW, roi, 0.005)


def test_plane_fit_distorted_camera_uses_the_kdtree():
    K = Intrinsics(80, 60, 70.0, 70.0, 39.5, 29.5, "opencv", (-0.1, 0.01, 0.0, 0.0, 0.0))
    pred, ref, roi = noisy_pair(K)
    assert M.plane_fit_rmse(pred, ref, K, roi=roi, radius_m=0.012).method == "kdtree"
    with pytest.raises(M.MetricInputError, match="distortion"):
        M.plane_fit_rmse(pred, ref, K, roi=roi, radius_m=0.012, method="grid")


def test_plane_fit_of_a_noise_free_plane():
    rng = np.random.default_rng(11)
    v, u = np.mgrid[0:60, 0:80]
    # a true 3D plane has 1/z linear in the pixel coordinates; ~2 mm pixels at 1 m: ~20 neighbours in 5 mm
    tilted = (1.0 / (1.0 - 0.0008 * (u - 40) - 0.0004 * (v - 30))).astype(np.float32)
    exact = M.plane_fit_rmse(tilted.copy(), tilted, K_NARROW, radius_m=0.005)
    assert exact.rmse_mm < 1e-3           # float32 depth rounding only (< 1 um)
    assert exact.n_used == tilted.size
    assert np.median(exact.neighbors) >= 15
    # raw noisy input gives the noise level (noise well below the 2 mm pixel footprint, fronto-parallel plane)
    flat = np.full((60, 80), 1.0, np.float32)
    sigma = 0.0005
    noisy = (flat + rng.normal(0, sigma, flat.shape)).astype(np.float32)
    assert M.plane_fit_rmse(noisy, flat, K_NARROW, radius_m=0.005).rmse_mm == pytest.approx(sigma * 1000, rel=0.05)
    # noise at the pixel footprint and above: the closest-point distance under-estimates it (documented bias)
    loud = (flat + rng.normal(0, 0.002, flat.shape)).astype(np.float32)
    assert M.plane_fit_rmse(loud, flat, K_NARROW, radius_m=0.005).rmse_mm < 0.6 * 2.0
    assert M.rmse_mm(loud, flat) == pytest.approx(2.0, rel=0.05)


def test_planes_are_reusable_across_predictions():
    pred, ref, roi = noisy_pair(K_SMALL)
    planes = M.fit_reference_planes(ref, K_SMALL, roi=roi, radius_m=0.012)
    for p in (pred, ref, pred + 0.002):
        a = M.plane_fit_rmse(p, ref, K_SMALL, roi=roi, planes=planes)
        b = M.plane_fit_rmse(p, ref, K_SMALL, roi=roi, radius_m=0.012)
        assert a.rmse_mm == b.rmse_mm


def test_empty_reference_gives_nan_not_an_error():
    pred, ref, roi = noisy_pair(K_SMALL)
    empty = np.full_like(ref, np.nan)
    assert np.isnan(M.plane_fit_rmse(pred, empty, K_SMALL, roi=roi).rmse_mm)
    metrics, bins = M.frame_metrics(pred, empty, K_SMALL, roi=roi)
    assert metrics["n_reference"] == 0 and np.isnan(metrics["rmse_mm"]) and bins == []


# ------------------------------------------------------------------------------- one frame
def test_frame_metrics_bins_add_up():
    pred, ref, roi = noisy_pair(K_SMALL, base=0.45, slant=(0.006, 0.004))
    cfg = M.MetricConfig(radius_m=0.012, depth_bin_m=0.1)
    metrics, bins = M.frame_metrics(pred, ref, K_SMALL, roi=roi, config=cfg)
    want = brute_pixels(pred, ref, roi)
    assert metrics["mae_mm"] == pytest.approx(want["mae_mm"], rel=1e-9)
    assert len(bins) >= 3
    n = sum(b["n_valid"] for b in bins)
    assert n == metrics["n_valid"]
    assert sum(b["n_valid"] * b["mae_mm"] for b in bins if b["n_valid"]) / n == pytest.approx(metrics["mae_mm"], rel=1e-9)
    pf_n = sum(b["plane_fit_n"] for b in bins)
    assert pf_n == metrics["plane_fit_n"]
    pooled = np.sqrt(sum(b["plane_fit_n"] * b["plane_fit_rmse_mm"] ** 2 for b in bins if b["plane_fit_n"]) / pf_n)
    assert pooled == pytest.approx(metrics["plane_fit_rmse_mm"], rel=1e-9)
    assert sum(b["plane_fit_excluded"] for b in bins) == metrics["plane_fit_excluded"]
    for b in bins:   # every pixel of the bin lies in [lo, hi)
        assert b["bin_hi_m"] - b["bin_lo_m"] == pytest.approx(0.1)
    assert set(metrics) == set(M.UNITS)
