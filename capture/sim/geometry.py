"""Triangle-mesh primitives and small rotation helpers for the simulator (pure numpy).

Every primitive is returned in its own local frame as ``(vertices (V, 3) float64 metres,
triangles (T, 3) int64)`` with outward-facing triangles (counter-clockwise seen from outside).

Example:
    >>> v, t = box((1.0, 2.0, 3.0))
    >>> v.shape, t.shape
    ((8, 3), (12, 3))
    >>> float(np.abs(v).max(axis=0)[2])
    1.5
"""
from __future__ import annotations

import numpy as np


def rot_x(a: float) -> np.ndarray:
    """3x3 rotation by ``a`` radians about x."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> np.ndarray:
    """3x3 rotation by ``a`` radians about y."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> np.ndarray:
    """3x3 rotation by ``a`` radians about z."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def pose(R: np.ndarray | None = None, t=(0.0, 0.0, 0.0)) -> np.ndarray:
    """4x4 homogeneous matrix from a rotation (3x3) and a translation (metres)."""
    m = np.eye(4)
    if R is not None:
        m[:3, :3] = R
    m[:3, 3] = t
    return m


def quad(width: float, height: float) -> tuple[np.ndarray, np.ndarray]:
    """A rectangle in the local x-y plane centred at the origin, facing +z."""
    w, h = width / 2, height / 2
    v = np.array([[-w, -h, 0.0], [w, -h, 0.0], [w, h, 0.0], [-w, h, 0.0]])
    return v, np.array([[0, 1, 2], [0, 2, 3]])


def box(size) -> tuple[np.ndarray, np.ndarray]:
    """An axis-aligned box of ``size`` (sx, sy, sz) metres centred at the origin."""
    s = np.asarray(size, dtype=np.float64) / 2
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64) * s
    # corner index = 4*(x>0) + 2*(y>0) + (z>0)
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = []
    for a, b, c, d in faces:
        tris += [(a, b, c), (a, c, d)]
    return corners, np.array(tris)


def _lathe(profile_r: np.ndarray, profile_z: np.ndarray, segments: int) -> tuple[np.ndarray, np.ndarray]:
    """Revolve a profile (r, z) from bottom pole to top pole about the z axis."""
    n = len(profile_r)
    ang = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    inner = [np.column_stack([ring * profile_r[i], np.full(segments, profile_z[i])]) for i in range(1, n - 1)]
    v = np.concatenate([[[0.0, 0.0, profile_z[0]]], *inner, [[0.0, 0.0, profile_z[-1]]]])
    top = len(v) - 1
    tris = []
    for j in range(segments):  # bottom cap fan
        tris.append((0, 1 + (j + 1) % segments, 1 + j))
    for i in range(n - 3):
        a0, b0 = 1 + i * segments, 1 + (i + 1) * segments
        for j in range(segments):
            j1 = (j + 1) % segments
            tris += [(a0 + j, a0 + j1, b0 + j1), (a0 + j, b0 + j1, b0 + j)]
    last = 1 + (n - 3) * segments
    for j in range(segments):  # top cap fan
        tris.append((last + j, last + (j + 1) % segments, top))
    return v, np.array(tris)


def sphere(radius: float, *, segments: int = 20, rings: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """A UV sphere centred at the origin."""
    th = np.linspace(np.pi, 0, rings + 1)
    return _lathe(radius * np.sin(th), radius * np.cos(th), segments)


def capsule(radius: float, length: float, *, segments: int = 12, cap_rings: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """A capsule along the local z axis from z = 0 down to z = -length (radius included).

    Limbs hang from their joint at the origin, so a rotation of the part is a rotation
    about the joint.
    """
    th = np.linspace(0, np.pi / 2, cap_rings + 1)
    bottom_r, bottom_z = radius * np.sin(th), -length + radius - radius * np.cos(th)
    top_r, top_z = radius * np.cos(th), -radius + radius * np.sin(th)
    r = np.concatenate([bottom_r, top_r])
    z = np.concatenate([bottom_z, top_z])
    return _lathe(r, z, segments)
