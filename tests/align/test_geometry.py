"""Features, lifting, the extrinsic fit and the ROI on the analytic test scene (no simulator)."""
import numpy as np
import pytest

from align.errors import FeatureError
from align.extrinsics import fit_extrinsics, reprojection_errors
from align.features import detect, lift, match, sample_depth
from align.residuals import outliers, robust_summary
from align.roi import background_depth, foreground_mask, nan_percentile_axis0
from capture.camera import Intrinsics, Transform
from tests.align.scene import Plane, Rect, cast, look_at, room, texture

K_A = Intrinsics(640, 480, 560.0, 560.0, 319.5, 239.5)
K_B = Intrinsics(480, 360, 420.0, 420.0, 239.5, 179.5, "opencv", (0.02, -0.03, 0.0, 0.0, 0.0))
T_world_a = look_at((0.0, 0.0, 0.0), (0.1, 0.1, 4.0))
T_b_a = Transform.from_rotvec([0.01, -0.04, 0.005], [0.125, 0.01, -0.006])


@pytest.fixture(scope="module")
def views():
    shapes = room()
    da, Pa, _ = cast(K_A, T_world_a, shapes)
    db, Pb, _ = cast(K_B, T_b_a @ T_world_a, shapes)
    return da.astype(np.float32), texture(Pa), db.astype(np.float32), texture(Pb)


def test_sift_has_no_half_resolution_offset(views):
    _, img, _, _ = views
    from scipy.spatial import cKDTree

    full = detect(img, max_features=2000)
    half = detect(img, max_features=2000, scale=0.5)
    d, i = cKDTree(full.xy).query(half.xy)
    ok = d < 1.0
    assert ok.sum() > 100
    assert np.all(np.abs(np.median(half.xy[ok] - full.xy[i[ok]], axis=0)) < 0.06)


@pytest.mark.parametrize("kind", ["sift", "orb", "akaze"])
def test_matches_lift_and_fit_recover_the_true_transform(views, kind):
    da, ca, db, cb = views
    fa, fb = detect(ca, kind=kind, max_features=1500), detect(cb, kind=kind, max_features=1500)
    ia, ib = match(fa, fb)
    assert ia.size > 60
    X = lift(fa.xy[ia], da, K_A)  # camera A points of A's keypoints
    ok = np.all(np.isfinite(X), axis=1)
    err = reprojection_errors(X[ok], fb.xy[ib][ok], T_b_a, K_B)
    assert np.median(err) < (0.5 if kind != "orb" else 1.5)  # matches are true correspondences
    fit = fit_extrinsics(X[ok], fb.xy[ib][ok], K_B)
    dt, dr = fit.T.error_to(T_b_a)
    tol = (0.002, 0.05) if kind == "sift" else (0.006, 0.15)
    assert dt < tol[0] and dr < tol[1], (kind, dt, dr)


def test_fit_with_outliers_and_too_few_points():
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.uniform(-1, 1, 300), rng.uniform(-0.7, 0.7, 300), rng.uniform(2, 5, 300)])
    px = K_B.project(T_b_a.apply(X)) + rng.normal(0, 0.3, (300, 2))
    px[:60] += rng.uniform(-40, 40, (60, 2))  # 20 % wrong matches
    fit = fit_extrinsics(X, px, K_B)
    dt, dr = fit.T.error_to(T_b_a)
    assert dt < 0.004 and dr < 0.05
    assert fit.inliers[60:].mean() > 0.95 and fit.inliers[:60].mean() < 0.2
    with pytest.raises(FeatureError, match="need at least"):
        fit_extrinsics(X[:5], px[:5], K_B)


def test_sample_depth_refuses_edges():
    d = np.full((10, 10), 2.0, np.float32)
    d[:, 5:] = 4.0
    z = sample_depth(d, np.array([[2.3, 3.5], [4.5, 3.0], [7.2, 6.9], [12.0, 1.0]]))
    assert z[0] == pytest.approx(2.0) and np.isnan(z[1]) and z[2] == pytest.approx(4.0) and np.isnan(z[3])


def test_roi_marks_what_stands_in_front_of_the_background():
    K = Intrinsics(160, 120, 150.0, 150.0, 79.5, 59.5)
    wall = [Plane((0, 0, 4.0), (0, 0.2, 1))]
    bg, _, _ = cast(K, Transform.identity(), wall)
    frames = []
    for x in (-0.8, 0.0, 0.8):  # a person moving in front of the wall
        d, _, which = cast(K, Transform.identity(), wall + [Rect((x, 0.0, 2.0), (0.2, 0, 0), (0, 0.6, 0))])
        frames.append((d.astype(np.float32), which == 1))
    model = background_depth(np.stack([f[0] for f in frames] * 3))
    assert np.nanmax(np.abs(model - bg)) < 1e-4
    for d, person in frames:
        m = foreground_mask(d, model, min_area_px=20)
        assert (m == person).mean() > 0.995


@pytest.mark.parametrize("percentile", [0.0, 12.5, 50.0, 90.0, 100.0])
def test_nan_percentile_equals_numpys_per_pixel(percentile):
    rng = np.random.default_rng(int(percentile))
    stack = rng.uniform(0.5, 5.0, (17, 12, 9)).astype(np.float32)
    stack[rng.random(stack.shape) < 0.6] = np.nan
    stack[:, 0, 0] = np.nan                     # a pixel never measured
    stack[1:, 0, 1] = np.nan                    # a pixel measured once
    got, count = nan_percentile_axis0(stack, percentile)
    for i, j in np.ndindex(stack.shape[1:]):
        column = stack[:, i, j]
        valid = column[np.isfinite(column)]
        assert count[i, j] == valid.size
        if valid.size == 0:
            assert np.isnan(got[i, j])
        else:
            assert got[i, j] == pytest.approx(np.percentile(valid.astype(np.float64), percentile), rel=1e-6)


def test_residual_helpers():
    v = np.r_[np.full(50, 0.01), 0.5, np.nan]
    assert list(np.flatnonzero(outliers(v))) == [50, 51]
    s = robust_summary([1.0, 2.0, 3.0, np.nan])
    assert s["n"] == 3 and s["median"] == 2.0


def _smooth_texture(P: np.ndarray) -> np.ndarray:
    """A grey texture fixed to the surfaces, smooth enough not to alias: (H, W) uint8."""
    P = np.nan_to_num(P)
    v = (0.5 + 0.18 * np.sin(31 * P[..., 0] + 7 * P[..., 2]) * np.cos(27 * P[..., 1] - 5 * P[..., 2])
         + 0.12 * np.sin(53 * P[..., 1] + 41 * P[..., 0] + 19 * P[..., 2]))
    return np.clip(v * 255, 0, 255).astype(np.uint8)


def test_patch_refinement_finds_where_the_hq_patch_lies():
    """refine_offsets against the analytic projection: starts up to 1 px off land within hundredths of a pixel
    (camera B has lens distortion and another focal length); a textureless patch is refused."""
    from align.features import hq_patches, refine_offsets

    shapes = room()
    da, Pa, _ = cast(K_A, T_world_a, shapes)
    _, Pb, _ = cast(K_B, T_b_a @ T_world_a, shapes)
    ca, cb = _smooth_texture(Pa), _smooth_texture(Pb)
    rng = np.random.default_rng(0)
    xy = np.column_stack([rng.uniform(20, 620, 300), rng.uniform(20, 460, 300)])
    pat = hq_patches(ca, da.astype(np.float32), K_A, xy, sigma_px=0.0)
    true = K_B.project(T_b_a.apply(pat.centre))  # where each A keypoint's surface point lies in B
    start = true + rng.uniform(-1, 1, true.shape)
    off, ok = refine_offsets(pat, cb, K_B, T_b_a, start, sigma_px=0.0)
    inside = np.all(np.isfinite(true), axis=1)
    assert ok.sum() > 0.85 * inside.sum()
    err = np.linalg.norm(start + off - true, axis=1)[ok]
    assert np.median(err) < 0.05 and np.percentile(err, 90) < 0.15, (np.median(err), np.percentile(err, 90))
    assert np.all(off[~ok] == 0)
    flat = np.full_like(cb, 128)
    _, ok_flat = refine_offsets(pat, flat, K_B, T_b_a, start, sigma_px=0.0)
    assert not ok_flat.any()
