"""ChArUco-board calibration: the alternative to colour features when a board was recorded.

Pure numpy/OpenCV (``cv2.aruco``), no I/O. A ChArUco board gives, in every colour image that
sees it, sub-pixel chessboard corners with identities; :func:`board_pose` turns them into the
board's pose in that camera (PnP on the corners). When two cameras see the board at the same
time, ``T_a_b = T_a_board * T_b_board^-1``; :func:`extrinsics_from_boards` combines several such
views robustly (rotation: chordal mean of the per-view rotations after dropping outliers;
translation: component-wise median).

The board of the SSDD authors' lab (``alr-internship/self-supervised-depth-denoising``) is 7 x 5
squares, ``DICT_4X4_250`` markers of 0.8 square; only the square length must be given in metres.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from align.errors import AlignError, CalibrationBoardError
from capture.camera import Intrinsics, Transform


@dataclass(frozen=True)
class BoardSpec:
    """A ChArUco board: squares across and down, square and marker side (metres), dictionary."""

    squares_x: int = 7
    squares_y: int = 5
    square_m: float = 0.04
    marker_m: float = 0.032
    dictionary: str = "DICT_4X4_250"
    legacy: bool = False

    def __post_init__(self) -> None:
        if self.squares_x < 2 or self.squares_y < 2:
            raise AlignError(f"board: needs at least 2x2 squares, got {self.squares_x}x{self.squares_y}")
        if not (0 < self.marker_m < self.square_m):
            raise AlignError(f"board: marker side {self.marker_m} m must be positive and smaller than the square "
                             f"side {self.square_m} m")
        if not hasattr(cv2.aruco, self.dictionary):
            raise AlignError(f"board: unknown ArUco dictionary {self.dictionary!r}")

    @classmethod
    def parse(cls, text: str) -> "BoardSpec":
        """``"7x5:0.04:0.032[:DICT_4X4_250]"`` -> BoardSpec (squares, square m, marker m, dictionary)."""
        try:
            parts = text.split(":")
            sx, sy = (int(v) for v in parts[0].lower().split("x"))
            square, marker = float(parts[1]), float(parts[2])
            dictionary = parts[3] if len(parts) > 3 else "DICT_4X4_250"
        except (ValueError, IndexError):
            raise AlignError(f"--board: expected SXxSY:SQUARE_M:MARKER_M[:DICT], e.g. 7x5:0.04:0.032, got {text!r}") from None
        return cls(sx, sy, square, marker, dictionary)

    def board(self):
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        b = cv2.aruco.CharucoBoard((self.squares_x, self.squares_y), self.square_m, self.marker_m, d)
        if self.legacy:
            b.setLegacyPattern(True)
        return b

    def corner_points(self) -> np.ndarray:
        """``(M, 3)`` board-frame coordinates of the inner chessboard corners (z = 0), metres."""
        return np.asarray(self.board().getChessboardCorners(), np.float64).reshape(-1, 3)

    def render(self, px_per_square: int = 80, margin_px: int = 40) -> np.ndarray:
        """The board as a grey uint8 image (for printing, and for tests)."""
        size = (self.squares_x * px_per_square + 2 * margin_px, self.squares_y * px_per_square + 2 * margin_px)
        return self.board().generateImage(size, marginSize=margin_px, borderBits=1)


def detect_board(image: np.ndarray, spec: BoardSpec) -> tuple[np.ndarray, np.ndarray]:
    """ChArUco corners in an RGB or grey uint8 image: ``(xy (N, 2) float64, ids (N,) int)``; empty if none."""
    img = np.asarray(image)
    grey = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 else img
    det = cv2.aruco.CharucoDetector(spec.board())
    corners, ids, _, _ = det.detectBoard(grey)
    if ids is None or len(ids) == 0:
        return np.empty((0, 2)), np.empty(0, np.int64)
    return np.asarray(corners, np.float64).reshape(-1, 2), np.asarray(ids, np.int64).ravel()


@dataclass
class BoardPose:
    """The board seen by one camera: ``T_cam_board``, corners used, reprojection RMS (px)."""

    T_cam_board: Transform
    n_corners: int
    rms_px: float


def board_pose(xy: np.ndarray, ids: np.ndarray, spec: BoardSpec, K: Intrinsics, *, min_corners: int = 6) -> BoardPose:
    """PnP of the detected corners against the board geometry (iterative, distortion honoured)."""
    if len(ids) < min_corners:
        raise CalibrationBoardError(f"ChArUco board: only {len(ids)} corners found, need {min_corners}")
    obj = spec.corner_points()[ids]
    img = np.asarray(xy, np.float64).reshape(-1, 2)
    ok, rvec, tvec = cv2.solvePnP(obj, img, K.K, K.dist_coeffs, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise CalibrationBoardError("ChArUco board: no pose fits the detected corners")
    ok, rvec, tvec = cv2.solvePnP(obj, img, K.K, K.dist_coeffs, rvec, tvec, useExtrinsicGuess=True,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    T = Transform.from_rotvec(rvec.ravel(), tvec.ravel())
    err = np.linalg.norm(K.project(T.apply(obj)) - img, axis=1)
    return BoardPose(T, int(len(ids)), float(np.sqrt(np.mean(err ** 2))))


def extrinsics_from_boards(poses_a: list[Transform], poses_b: list[Transform]) -> tuple[Transform, dict]:
    """``T_a_b`` from simultaneous board poses ``T_a_board``, ``T_b_board`` (one pair per view).

    Returns the transform and its spread over the views (``rotation_deg``, ``translation_mm``: RMS
    deviation of the per-view estimates from the result; ``views``).
    """
    if len(poses_a) != len(poses_b) or not poses_a:
        raise CalibrationBoardError("ChArUco calibration needs at least one view of the board seen by both cameras")
    per = [a @ b.inverse() for a, b in zip(poses_a, poses_b)]
    rots = Rotation.from_matrix(np.stack([T.R for T in per]))
    t = np.stack([T.t for T in per])
    keep = np.ones(len(per), bool)
    for _ in range(2):  # drop views far from the consensus (a misdetected board)
        R_mean = rots[keep].mean()
        ang = np.degrees((rots * R_mean.inv()).magnitude())
        t_med = np.median(t[keep], axis=0)
        dist = np.linalg.norm(t - t_med, axis=1)
        if keep.sum() > 2:
            keep = (ang < max(1.0, 4 * np.median(ang))) & (dist < max(0.01, 4 * np.median(dist)))
    R = rots[keep].mean().as_matrix()
    T = Transform.from_rt(R, np.median(t[keep], axis=0))
    dev = [T.error_to(p) for p, k in zip(per, keep) if k]
    return T, {"views": int(keep.sum()), "rotation_deg": float(np.sqrt(np.mean([d[1] ** 2 for d in dev]))),
               "translation_mm": float(1e3 * np.sqrt(np.mean([d[0] ** 2 for d in dev])))}
