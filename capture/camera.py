"""Camera intrinsics with an explicit distortion model, and rigid transforms.

Pure numpy, no I/O. The types live in ``capture`` (the bottom layer) because the simulator
must project with them and ``capture`` never imports ``align``; ``align`` builds its
projection and warping on top of them.

Conventions
-----------
* Pixel coordinates: ``(u, v)`` with the centre of the top-left pixel at ``(0, 0)`` (OpenCV).
* Camera frame: x right, y down, z forward, metres.
* Distortion: ``"none"`` or ``"opencv"`` with coefficients in OpenCV order
  ``k1, k2, p1, p2, k3[, k4, k5, k6]`` (4, 5 or 8 values; 8 is the rational model, which is
  also Azure Kinect's "Brown-Conrady rational 6KT").
* Transforms are named ``T_dst_src``: ``T_lq_hq.apply(p_hq)`` gives the point in LQ coordinates.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from capture.errors import CalibrationError

DISTORTION_MODELS = ("none", "opencv")


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of one stream plus lens distortion.

    Example:
        >>> K = Intrinsics(640, 480, fx=600.0, fy=600.0, cx=319.5, cy=239.5)
        >>> uv = K.project(np.array([[0.0, 0.0, 2.0]]))
        >>> uv.tolist()
        [[319.5, 239.5]]
        >>> K.unproject(uv, np.array([2.0])).tolist()
        [[0.0, 0.0, 2.0]]
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion_model: str = "none"
    coeffs: tuple[float, ...] = field(default=())

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0:
            raise CalibrationError(f"intrinsics: image size must be positive, got {self.width}x{self.height}")
        if not (np.isfinite(self.fx) and np.isfinite(self.fy) and self.fx > 0 and self.fy > 0):
            raise CalibrationError(f"intrinsics: focal lengths must be positive, got fx={self.fx} fy={self.fy}")
        if self.distortion_model not in DISTORTION_MODELS:
            raise CalibrationError(
                f"intrinsics: unknown distortion model {self.distortion_model!r} (expected one of {DISTORTION_MODELS})"
            )
        coeffs = tuple(float(c) for c in self.coeffs)
        if self.distortion_model == "none" and any(coeffs):
            raise CalibrationError("intrinsics: distortion model 'none' cannot have non-zero coefficients")
        if self.distortion_model == "opencv" and len(coeffs) not in (4, 5, 8):
            raise CalibrationError(f"intrinsics: 'opencv' distortion needs 4, 5 or 8 coefficients, got {len(coeffs)}")
        object.__setattr__(self, "coeffs", coeffs)

    # ----------------------------------------------------------------- basic forms
    @property
    def K(self) -> np.ndarray:
        """3x3 camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        """Distortion coefficients as OpenCV expects them (8 values, zeros where unused)."""
        d = np.zeros(8)
        d[: len(self.coeffs)] = self.coeffs
        return d

    @property
    def has_distortion(self) -> bool:
        return any(self.coeffs)

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape as numpy sees it: (height, width)."""
        return (self.height, self.width)

    def to_dict(self) -> dict:
        return {
            "width": int(self.width),
            "height": int(self.height),
            "fx": float(self.fx),
            "fy": float(self.fy),
            "cx": float(self.cx),
            "cy": float(self.cy),
            "distortion_model": self.distortion_model,
            "coeffs": [float(c) for c in self.coeffs],
        }

    @classmethod
    def from_dict(cls, d: dict) -> "Intrinsics":
        try:
            return cls(
                int(d["width"]), int(d["height"]), float(d["fx"]), float(d["fy"]), float(d["cx"]), float(d["cy"]),
                d.get("distortion_model", "none"), tuple(d.get("coeffs", ())),
            )
        except KeyError as exc:
            raise CalibrationError(f"intrinsics: missing field {exc.args[0]!r}") from None

    def scaled(self, width: int, height: int) -> "Intrinsics":
        """The same camera at another resolution (e.g. 1280x720 -> 640x360)."""
        sx, sy = width / self.width, height / self.height
        return Intrinsics(width, height, self.fx * sx, self.fy * sy, (self.cx + 0.5) * sx - 0.5,
                          (self.cy + 0.5) * sy - 0.5, self.distortion_model, self.coeffs)

    def without_distortion(self) -> "Intrinsics":
        return Intrinsics(self.width, self.height, self.fx, self.fy, self.cx, self.cy)

    # ---------------------------------------------------------- distortion on the normalised plane
    def distort(self, xy: np.ndarray) -> np.ndarray:
        """Apply lens distortion to normalised coordinates ``(N, 2)`` (OpenCV model)."""
        if not self.has_distortion:
            return np.asarray(xy, dtype=np.float64)
        k1, k2, p1, p2, k3, k4, k5, k6 = self.dist_coeffs
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.stack([xd, yd], axis=1)

    def undistort(self, xy_distorted: np.ndarray, iterations: int = 20) -> np.ndarray:
        """Invert :meth:`distort` by fixed-point iteration (as ``cv2.undistortPoints`` does)."""
        xy_d = np.asarray(xy_distorted, dtype=np.float64)
        if not self.has_distortion:
            return xy_d
        k1, k2, p1, p2, k3, k4, k5, k6 = self.dist_coeffs
        x, y = xy_d[:, 0].copy(), xy_d[:, 1].copy()
        for _ in range(iterations):
            r2 = x * x + y * y
            icdist = (1 + r2 * (k4 + r2 * (k5 + r2 * k6))) / (1 + r2 * (k1 + r2 * (k2 + r2 * k3)))
            dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
            dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
            x = (xy_d[:, 0] - dx) * icdist
            y = (xy_d[:, 1] - dy) * icdist
        return np.stack([x, y], axis=1)

    # ------------------------------------------------------------------ projection
    def project(self, points: np.ndarray) -> np.ndarray:
        """Camera-frame points ``(N, 3)`` in metres to pixels ``(N, 2)``; z <= 0 gives NaN."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        z = p[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = p[:, :2] / np.where(z > 0, z, np.nan)[:, None]
        xy = self.distort(xy)
        return np.stack([self.fx * xy[:, 0] + self.cx, self.fy * xy[:, 1] + self.cy], axis=1)

    def pixel_to_normalized(self, uv: np.ndarray) -> np.ndarray:
        """Pixels ``(N, 2)`` to undistorted normalised coordinates ``(N, 2)``."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        xy_d = np.stack([(uv[:, 0] - self.cx) / self.fx, (uv[:, 1] - self.cy) / self.fy], axis=1)
        return self.undistort(xy_d)

    def unproject(self, uv: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """Pixels ``(N, 2)`` with z-depth ``(N,)`` in metres to camera-frame points ``(N, 3)``."""
        xy = self.pixel_to_normalized(uv)
        z = np.asarray(depth, dtype=np.float64).reshape(-1)
        return np.stack([xy[:, 0] * z, xy[:, 1] * z, z], axis=1)

    def pixel_grid(self) -> np.ndarray:
        """All pixel centres as ``(H*W, 2)`` in row-major order."""
        v, u = np.mgrid[0 : self.height, 0 : self.width]
        return np.stack([u.ravel(), v.ravel()], axis=1).astype(np.float64)

    def ray_grid(self) -> np.ndarray:
        """Undistorted viewing rays with z = 1 for every pixel, ``(H, W, 3)``."""
        xy = self.pixel_to_normalized(self.pixel_grid())
        rays = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1)
        return rays.reshape(self.height, self.width, 3)

    def depth_to_points(self, depth: np.ndarray) -> np.ndarray:
        """A depth image ``(H, W)`` in metres (NaN = none) to points ``(H, W, 3)`` (NaN where none)."""
        if depth.shape != self.shape:
            raise CalibrationError(f"depth image is {depth.shape[1]}x{depth.shape[0]}, intrinsics are {self.width}x{self.height}")
        return self.ray_grid() * depth[..., None].astype(np.float64)


@dataclass(frozen=True)
class Transform:
    """A rigid transform ``T_dst_src`` as a 4x4 matrix in metres.

    Example:
        >>> T_b_a = Transform.from_rt(np.eye(3), [0.1, 0.0, 0.0])
        >>> T_b_a.apply(np.zeros((1, 3))).tolist()
        [[0.1, 0.0, 0.0]]
        >>> (T_b_a.inverse() @ T_b_a).is_close(Transform.identity())
        True
    """

    matrix: np.ndarray

    def __post_init__(self) -> None:
        m = np.asarray(self.matrix, dtype=np.float64)
        if m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise CalibrationError(f"transform must be a finite 4x4 matrix, got shape {m.shape}")
        R = m[:3, :3]
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0 or not np.allclose(m[3], [0, 0, 0, 1]):
            raise CalibrationError("transform is not rigid (rotation not orthonormal or last row not 0 0 0 1)")
        m.setflags(write=False)
        object.__setattr__(self, "matrix", m)

    @classmethod
    def identity(cls) -> "Transform":
        return cls(np.eye(4))

    @classmethod
    def from_rt(cls, R, t) -> "Transform":
        m = np.eye(4)
        m[:3, :3] = np.asarray(R, dtype=np.float64)
        m[:3, 3] = np.asarray(t, dtype=np.float64).reshape(3)
        return cls(m)

    @classmethod
    def from_rotvec(cls, rotvec, t) -> "Transform":
        from scipy.spatial.transform import Rotation

        return cls.from_rt(Rotation.from_rotvec(np.asarray(rotvec, dtype=np.float64)).as_matrix(), t)

    @classmethod
    def from_list(cls, rows) -> "Transform":
        return cls(np.array(rows, dtype=np.float64))

    def to_list(self) -> list[list[float]]:
        return [[float(x) for x in row] for row in self.matrix]

    @property
    def R(self) -> np.ndarray:
        return self.matrix[:3, :3]

    @property
    def t(self) -> np.ndarray:
        return self.matrix[:3, 3]

    def rotvec(self) -> np.ndarray:
        from scipy.spatial.transform import Rotation

        return Rotation.from_matrix(self.R).as_rotvec()

    def inverse(self) -> "Transform":
        return Transform.from_rt(self.R.T, -self.R.T @ self.t)

    def __matmul__(self, other: "Transform") -> "Transform":
        return Transform(self.matrix @ other.matrix)

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Transform points ``(..., 3)``."""
        p = np.asarray(points, dtype=np.float64)
        return p @ self.R.T + self.t

    def rotation_angle_deg(self) -> float:
        R = self.R  # atan2 form: exact near 0 deg, where arccos of the trace loses ~1e-6 deg
        s = 0.5 * np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
        return float(np.degrees(np.arctan2(s, (np.trace(R) - 1.0) / 2.0)))

    def is_close(self, other: "Transform", atol: float = 1e-9) -> bool:
        return bool(np.allclose(self.matrix, other.matrix, atol=atol))

    def error_to(self, other: "Transform") -> tuple[float, float]:
        """(translation error in metres, rotation error in degrees) of ``self`` against ``other``."""
        d = other.inverse() @ self
        return float(np.linalg.norm(d.t)), d.rotation_angle_deg()
