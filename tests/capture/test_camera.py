"""Camera model against OpenCV, the independent reference."""
import cv2
import numpy as np
import pytest

from capture.camera import Intrinsics, Transform
from capture.errors import CalibrationError

RATIONAL = Intrinsics(640, 576, 504.2, 504.3, 322.1, 331.9, "opencv",
                      (0.52, -0.03, 1e-4, -2e-4, -0.003, 0.86, 0.05, -0.02))
BROWN = Intrinsics(640, 480, 600.0, 602.0, 318.0, 241.0, "opencv", (-0.12, 0.05, 0.001, -0.002, 0.0))


@pytest.mark.parametrize("K", [RATIONAL, BROWN, Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5)])
def test_project_matches_cv2_projectPoints(K):
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-0.5, 0.5, 200), rng.uniform(-0.4, 0.4, 200), rng.uniform(0.8, 3.0, 200)])
    ours = K.project(pts)
    ref, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K.K, K.dist_coeffs)
    np.testing.assert_allclose(ours, ref.reshape(-1, 2), atol=1e-6)


@pytest.mark.parametrize("K", [RATIONAL, BROWN])
def test_unproject_inverts_project(K):
    rng = np.random.default_rng(1)
    pts = np.column_stack([rng.uniform(-0.4, 0.4, 100), rng.uniform(-0.3, 0.3, 100), rng.uniform(1.0, 2.0, 100)])
    back = K.unproject(K.project(pts), pts[:, 2])
    np.testing.assert_allclose(back, pts, atol=1e-6)


def test_undistort_matches_cv2_undistortPoints():
    uv = np.array([[10.0, 20.0], [320.0, 240.0], [600.0, 400.0]])
    ours = BROWN.pixel_to_normalized(uv)
    ref = cv2.undistortPoints(uv.reshape(-1, 1, 2), BROWN.K, BROWN.dist_coeffs).reshape(-1, 2)
    np.testing.assert_allclose(ours, ref, atol=1e-5)


def test_points_behind_camera_project_to_nan():
    K = Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5)
    assert np.isnan(K.project(np.array([[0.0, 0.0, -1.0]]))).all()


def test_depth_to_points_and_roundtrip_dict():
    K = Intrinsics(4, 3, 2.0, 2.0, 1.5, 1.0)
    depth = np.full((3, 4), 2.0, np.float32)
    depth[0, 0] = np.nan
    pts = K.depth_to_points(depth)
    assert np.isnan(pts[0, 0]).all()
    np.testing.assert_allclose(pts[1, 3], [(3 - 1.5) / 2 * 2, 0.0, 2.0])
    assert Intrinsics.from_dict(RATIONAL.to_dict()) == RATIONAL


def test_scaled_keeps_the_field_of_view():
    K = Intrinsics(1280, 720, 900.0, 900.0, 639.5, 359.5)
    half = K.scaled(640, 360)
    assert (half.fx, half.cx, half.cy) == (450.0, 319.5, 179.5)


@pytest.mark.parametrize("kwargs, fragment", [
    (dict(fx=-1.0), "focal"),
    (dict(distortion_model="fisheye"), "unknown distortion model"),
    (dict(distortion_model="opencv", coeffs=(0.1, 0.2, 0.3)), "4, 5 or 8"),
    (dict(coeffs=(0.1,)), "non-zero"),
])
def test_impossible_intrinsics_are_refused(kwargs, fragment):
    base = dict(width=64, height=48, fx=50.0, fy=50.0, cx=31.5, cy=23.5)
    with pytest.raises(CalibrationError, match=fragment):
        Intrinsics(**{**base, **kwargs})


def test_transform_algebra():
    T_b_a = Transform.from_rotvec([0.1, -0.2, 0.3], [0.05, 0.0, -0.02])
    T_c_b = Transform.from_rotvec([0.0, 0.4, 0.0], [0.0, 0.1, 0.0])
    p = np.array([[0.3, -0.2, 1.5]])
    np.testing.assert_allclose((T_c_b @ T_b_a).apply(p), T_c_b.apply(T_b_a.apply(p)))
    np.testing.assert_allclose(T_b_a.inverse().apply(T_b_a.apply(p)), p, atol=1e-12)
    dt, dr = T_b_a.error_to(T_b_a)
    assert dt < 1e-12 and dr < 1e-9
    assert abs(Transform.from_rotvec([0, 0, np.radians(2.0)], [0, 0, 0]).rotation_angle_deg() - 2.0) < 1e-9


def test_non_rigid_matrix_is_refused():
    m = np.eye(4)
    m[0, 0] = 2.0
    with pytest.raises(CalibrationError, match="not rigid"):
        Transform(m)
