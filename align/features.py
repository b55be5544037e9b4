"""Colour features: detection, matching, and lifting HQ feature pixels to 3D (the set U of eq. 31).

Pure numpy/OpenCV, no I/O. Detection runs once per frame; everything downstream (matching,
the time-shift loss, the extrinsic fit) reuses the same :class:`Features`.

* :func:`detect` -- SIFT (default), ORB or AKAZE keypoints and descriptors on a colour image.
* :func:`match` -- nearest-neighbour matching with Lowe's ratio test and a cross-check (a pair
  is kept only when each keypoint is the other's nearest neighbour).
* :func:`lift` -- HQ colour keypoints to 3D with the HQ depth registered to the HQ colour camera
  (``align.warp``); keypoints on depth discontinuities, or without depth, are refused.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from align.errors import AlignError, OptionError
from capture.camera import Intrinsics

FEATURES = ("sift", "orb", "akaze")


@dataclass(frozen=True)
class Features:
    """Keypoints of one image.

    Attributes:
        xy: ``(N, 2)`` float32 pixel coordinates (OpenCV convention, distorted image).
        descriptors: ``(N, D)`` uint8 (ORB/AKAZE, binary) or float32 (SIFT).
        kind: ``"sift"``, ``"orb"`` or ``"akaze"``.
    """

    xy: np.ndarray
    descriptors: np.ndarray
    kind: str

    def __len__(self) -> int:
        return int(self.xy.shape[0])

    @property
    def binary(self) -> bool:
        return self.kind in ("orb", "akaze")


def _detector(kind: str, max_features: int):
    if kind == "sift":
        # precise upscale: without it OpenCV's SIFT doubles the image with a half-pixel shift and
        # every keypoint comes out +0.25 px off (measured here), which biases T_ex and Delta
        return cv2.SIFT_create(nfeatures=max_features, enable_precise_upscale=True)
    if kind == "orb":
        return cv2.ORB_create(nfeatures=max_features, fastThreshold=10)
    if kind == "akaze":  # OpenCV 5 moved AKAZE to the contrib module
        create = getattr(cv2, "AKAZE_create", None) or cv2.xfeatures2d.AKAZE_create
        return create(threshold=5e-4)
    raise OptionError(f"unknown feature detector {kind!r} (choose from {', '.join(FEATURES)})", option="features")


def detect(image: np.ndarray, *, kind: str = "sift", max_features: int = 2000, mask: np.ndarray | None = None,
           scale: float = 1.0) -> Features:
    """Keypoints and descriptors of an RGB ``(H, W, 3)`` or grey ``(H, W)`` uint8 image.

    ``mask`` (``(H, W)`` bool) restricts detection, e.g. to pixels with depth. ``scale < 1``
    detects on a resized image (area filter) and returns full-resolution coordinates: SIFT's
    cost falls with the square of the scale (it doubles its input internally), its sub-pixel
    localisation stays.
    """
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim not in (2, 3):
        raise AlignError(f"feature detection needs an 8-bit image, got {img.dtype} with shape {img.shape}")
    grey = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 else img
    m = None if mask is None else np.asarray(mask, bool).astype(np.uint8) * 255
    if scale != 1.0:
        size = (max(8, round(grey.shape[1] * scale)), max(8, round(grey.shape[0] * scale)))
        sx, sy = grey.shape[1] / size[0], grey.shape[0] / size[1]
        grey = cv2.resize(grey, size, interpolation=cv2.INTER_AREA)
        m = None if m is None else cv2.resize(m, size, interpolation=cv2.INTER_NEAREST)
        f = detect(grey, kind=kind, max_features=max_features, mask=None if m is None else m > 0)
        xy = np.stack([(f.xy[:, 0] + 0.5) * sx - 0.5, (f.xy[:, 1] + 0.5) * sy - 0.5], axis=1).astype(np.float32)
        return Features(xy, f.descriptors, f.kind)
    det = _detector(kind, max_features)
    kps, desc = det.detectAndCompute(grey, m)
    if kind == "akaze" and len(kps) > max_features:  # AKAZE has no feature cap: keep the strongest
        order = np.argsort([-k.response for k in kps])[:max_features]
        kps = [kps[i] for i in order]
        desc = desc[order]
    xy = np.array([k.pt for k in kps], np.float32).reshape(-1, 2)
    if desc is None:
        desc = np.zeros((0, 32 if kind != "sift" else 128), np.uint8 if kind != "sift" else np.float32)
    return Features(xy, desc, kind)


def _knn(query: np.ndarray, train: np.ndarray, binary: bool, k: int):
    """``k`` nearest train descriptors for each query: indices and distances ``(Nq, k)``.

    Exact brute force, never FLANN: FLANN's randomised KD-trees draw from a process-global
    ``rand()``, so with probes matched in parallel threads the matches (and the fitted Delta, by
    up to ~0.2 ms) would depend on thread scheduling. Exact search makes alignment reproducible;
    it costs ~25 ms more per 2000x2000 SIFT match.
    """
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING if binary else cv2.NORM_L2)
    res = matcher.knnMatch(query, train, k=k)
    idx = np.full((len(query), k), -1, np.int64)
    dist = np.full((len(query), k), np.inf)
    for qi, ms in enumerate(res):
        for j, m in enumerate(ms[:k]):
            idx[qi, j], dist[qi, j] = m.trainIdx, m.distance
    return idx, dist


def match(a: Features, b: Features, *, ratio: float = 0.8, cross_check: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Match keypoints of ``a`` to ``b``; returns index arrays ``(ia, ib)`` of the kept pairs.

    Lowe's ratio test (nearest distance < ``ratio`` x second nearest) on ``a -> b``; with
    ``cross_check`` the pair is kept only if ``a``'s keypoint is also ``b``'s nearest neighbour.
    """
    if a.kind != b.kind:
        raise AlignError(f"cannot match {a.kind} features against {b.kind} features")
    if len(a) < 2 or len(b) < 2:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    da, db = a.descriptors, b.descriptors
    if not a.binary:
        da, db = da.astype(np.float32, copy=False), db.astype(np.float32, copy=False)
    idx, dist = _knn(da, db, a.binary, 2)
    good = (idx[:, 0] >= 0) & (dist[:, 0] < ratio * dist[:, 1])
    ia = np.flatnonzero(good)
    ib = idx[ia, 0]
    if cross_check and ia.size:
        back, _ = _knn(db[ib], da, a.binary, 1)  # nearest a-descriptor of each matched b-keypoint
        keep = back[:, 0] == ia
        ia, ib = ia[keep], ib[keep]
    # one a per b (ratio test alone allows several a on one b)
    _, first = np.unique(ib, return_index=True)
    first.sort()
    return ia[first], ib[first]


def sample_depth(depth: np.ndarray, xy: np.ndarray, *, edge_rel: float = 0.02) -> np.ndarray:
    """Depth at sub-pixel positions ``(N, 2)``: bilinear where the 2x2 neighbours are one surface.

    Returns ``(N,)`` float64 metres, NaN where a neighbour has no depth, the neighbours differ
    by more than ``edge_rel`` (a depth edge: the keypoint may belong to either surface), or the
    position is outside the image.
    """
    H, W = depth.shape
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    x0 = np.floor(xy[:, 0]).astype(np.int64)
    y0 = np.floor(xy[:, 1]).astype(np.int64)
    inside = (x0 >= 0) & (y0 >= 0) & (x0 + 1 < W) & (y0 + 1 < H)
    out = np.full(xy.shape[0], np.nan)
    if not inside.any():
        return out
    x0i, y0i = x0[inside], y0[inside]
    fx, fy = xy[inside, 0] - x0i, xy[inside, 1] - y0i
    q = np.stack([depth[y0i, x0i], depth[y0i, x0i + 1], depth[y0i + 1, x0i], depth[y0i + 1, x0i + 1]], 1).astype(np.float64)
    with np.errstate(invalid="ignore"):
        lo, hi = q.min(axis=1), q.max(axis=1)
        ok = np.isfinite(lo) & np.isfinite(hi) & (hi - lo <= edge_rel * lo)
    z = (q[:, 0] * (1 - fx) * (1 - fy) + q[:, 1] * fx * (1 - fy) + q[:, 2] * (1 - fx) * fy + q[:, 3] * fx * fy)
    out[np.flatnonzero(inside)[ok]] = z[ok]
    return out


def lift(xy: np.ndarray, depth_in_color: np.ndarray, K_color: Intrinsics, *, edge_rel: float = 0.02) -> np.ndarray:
    """Colour keypoints ``(N, 2)`` to 3D points ``(N, 3)`` in the colour camera frame (NaN rows: no depth).

    ``depth_in_color`` is the sensor's depth registered to its colour camera (``(H, W)`` float32 m).
    """
    z = sample_depth(depth_in_color, xy, edge_rel=edge_rel)
    return K_color.unproject(np.asarray(xy, np.float64), z)


def inverse_depth_gradient(depth_in_color: np.ndarray, xy: np.ndarray, *, step_px: float = 4.0,
                           edge_rel: float = 0.02) -> np.ndarray:
    """Gradient of inverse depth ``d(1/z)/d(x, y)`` at keypoints ``(N, 2)``: ``(N, 2)`` 1/(m px).

    Central differences over ``+-step_px``; 0 where a sample lies on an edge or has no depth.
    Inverse depth is affine in the image on a plane, so ``1/z(q + dq) = 1/z(q) + g . dq`` is exact
    there: the alignment loop uses it to re-sample a keypoint's depth when a lens model moves the
    keypoint's ray (:mod:`align.loop.effects.lens`).
    """
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    g = np.zeros_like(xy)
    for axis in (0, 1):
        e = np.zeros(2)
        e[axis] = step_px
        with np.errstate(invalid="ignore", divide="ignore"):
            d = (1 / sample_depth(depth_in_color, xy + e, edge_rel=edge_rel)
                 - 1 / sample_depth(depth_in_color, xy - e, edge_rel=edge_rel)) / (2 * step_px)
        g[:, axis] = np.where(np.isfinite(d), d, 0.0)
    return g


def track(frames: list[np.ndarray], anchor: int, xy: np.ndarray, *, fb_px: float = 0.5, win: int = 21,
          levels: int = 3) -> np.ndarray:
    """Follow keypoints from ``frames[anchor]`` through the neighbouring frames (pyramidal KLT).

    Tracking runs frame to frame outwards from the anchor in both directions; a point is kept in
    a frame only if tracking it back lands within ``fb_px`` of where it came from
    (forward-backward check), and is lost from then on.

    Args:
        frames: grey uint8 images ``(H, W)`` in time order. anchor: index of the frame of ``xy``.
        xy: ``(N, 2)`` float positions in ``frames[anchor]``.
    Returns:
        ``(len(frames), N, 2)`` float64 positions, NaN where lost.
    """
    n = len(frames)
    xy = np.asarray(xy, np.float32).reshape(-1, 2)
    out = np.full((n, xy.shape[0], 2), np.nan)
    out[anchor] = xy
    if xy.shape[0] == 0:
        return out
    params = dict(winSize=(win, win), maxLevel=levels,
                  criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01))

    def pyr(i):
        return frames[i]

    for step in (1, -1):
        alive = np.arange(xy.shape[0])
        pts = xy.copy()
        i = anchor
        while 0 <= i + step < n and alive.size:
            j = i + step
            p = pts.reshape(-1, 1, 2)
            nxt, st, _ = cv2.calcOpticalFlowPyrLK(pyr(i), pyr(j), p, None, **params)
            back, st2, _ = cv2.calcOpticalFlowPyrLK(pyr(j), pyr(i), nxt, None, **params)
            good = (st.ravel() == 1) & (st2.ravel() == 1) & (np.linalg.norm((back - p).reshape(-1, 2), axis=1) < fb_px)
            h, w = frames[j].shape[:2]
            q = nxt.reshape(-1, 2)
            good &= (q[:, 0] >= 0) & (q[:, 1] >= 0) & (q[:, 0] <= w - 1) & (q[:, 1] <= h - 1)
            alive, pts = alive[good], q[good]
            out[j, alive] = pts
            i = j
    return out


# --------------------------------------------------------------------------- photometric refinement
@dataclass(frozen=True)
class Patches:
    """HQ colour patches around keypoints, lifted to 3D: what :func:`refine_offsets` needs.

    Attributes:
        intensity: ``(N, P)`` float32 grey values of the (blurred) HQ colour image on a square grid
            of ``P = (2 r + 1)^2`` sub-pixel positions around each keypoint.
        points: ``(N, P, 3)`` those positions in the HQ colour camera frame, metres (NaN where the
            depth is missing or belongs to another surface than the keypoint's).
        centre: ``(N, 3)`` the keypoints themselves in the HQ colour camera frame.
    """

    intensity: np.ndarray
    points: np.ndarray
    centre: np.ndarray

    def __len__(self) -> int:
        return int(self.intensity.shape[0])

    def subset(self, index: np.ndarray) -> "Patches":
        return Patches(self.intensity[index], self.points[index], self.centre[index])


def _bilinear(image: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """``image`` sampled at ``xy`` ``(..., 2)`` (bilinear, NaN outside): shape ``xy.shape[:-1]``."""
    shp = xy.shape[:-1]
    q = np.asarray(xy, np.float32).reshape(-1, 2)
    n = q.shape[0]
    if n == 0:
        return np.zeros(shp, np.float32)
    q = np.concatenate([q, np.full((-n % 1024, 2), -1e4, np.float32)]).reshape(-1, 1024, 2)  # remap: < 32767 rows
    out = cv2.remap(np.asarray(image, np.float32), q[..., 0], q[..., 1], cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)
    return out.reshape(-1)[:n].reshape(shp)


def _blurred_grey(image: np.ndarray, sigma_px: float) -> np.ndarray:
    img = np.asarray(image)
    grey = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 else img
    grey = grey.astype(np.float32)
    return cv2.GaussianBlur(grey, (0, 0), sigma_px) if sigma_px > 0 else grey


def hq_patches(image: np.ndarray, depth_in_color: np.ndarray, K_color: Intrinsics, xy: np.ndarray, *,
               radius: int = 5, sigma_px: float = 0.8, edge_rel: float = 0.03) -> Patches:
    """Patches of the HQ colour ``image`` around keypoints ``xy`` ``(N, 2)``, lifted with the HQ depth
    registered to the colour camera (``depth_in_color``, ``(H, W)`` m). Grid step 1 px; the image is
    blurred by a Gaussian of ``sigma_px`` first (the simulator's and real sensors' colour images
    alias; the blur makes the intensities smooth enough for :func:`refine_offsets`' gradients).
    Patch pixels whose depth differs from the keypoint's by more than ``edge_rel`` (another surface)
    are left out (NaN points)."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    o = np.arange(-radius, radius + 1, dtype=np.float64)
    grid = np.stack(np.meshgrid(o, o), -1).reshape(-1, 2)
    P = xy[:, None, :] + grid[None]
    inten = _bilinear(_blurred_grey(image, sigma_px), P)
    zk = sample_depth(depth_in_color, xy, edge_rel=edge_rel)
    z = sample_depth(depth_in_color, P.reshape(-1, 2), edge_rel=edge_rel).reshape(P.shape[:2])
    with np.errstate(invalid="ignore"):
        z = np.where(np.abs(z - zk[:, None]) <= edge_rel * zk[:, None], z, np.nan)
    pts = K_color.unproject(P.reshape(-1, 2), z.ravel()).reshape(P.shape[0], P.shape[1], 3)
    return Patches(inten.astype(np.float32), pts, K_color.unproject(xy, zk))


def refine_offsets(patches: Patches, image: np.ndarray, K: Intrinsics, T_cam_hqcolor, xy: np.ndarray, *,
                   sigma_px: float = 1.0, iterations: int = 12, max_px: float = 2.0, min_valid: float = 0.6,
                   min_ncc: float = 0.8) -> tuple[np.ndarray, np.ndarray]:
    """Where each HQ patch lies in an LQ colour image, relative to the matched keypoint ``xy`` ``(N, 2)``.

    The patch's 3D points are mapped into ``image`` (camera ``K``) through ``T_cam_hqcolor`` (the
    current extrinsic estimate; it fixes the patch's shape, perspective included) and placed so that
    its keypoint falls on ``xy``; then a 2D offset ``t`` and an affine intensity change ``a I + b``
    are fitted by Gauss-Newton (Lucas-Kanade with gain and bias) to the ``sigma_px``-blurred image.
    ``xy + t`` is the keypoint's photometrically refined position. SIFT places the same texture at
    positions off by about 0.45 px (median) between the two cameras, the same every frame for
    still texture: that error does not average out over frames, and with the far features pulling
    little on the translation along the optical axis it put ``T_lq_hq`` 1-1.5 mm off in z on clean
    simulated sessions (``docs/worklog``, session 9). Patches cut that error about in half.

    Returns ``(offsets (N, 2) px, ok (N,) bool)``; ``ok`` is false (offset 0) where fewer than
    ``min_valid`` of a patch's pixels land in the image with depth, the offset leaves ``max_px``,
    the iteration does not settle, or the fitted patch correlates below ``min_ncc``.
    """
    N, P = patches.intensity.shape
    if N == 0:
        return np.zeros((0, 2)), np.zeros(0, bool)
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    L = _blurred_grey(image, sigma_px)
    gx = cv2.Sobel(L, cv2.CV_32F, 1, 0, ksize=1, scale=0.5)
    gy = cv2.Sobel(L, cv2.CV_32F, 0, 1, ksize=1, scale=0.5)
    with np.errstate(invalid="ignore"):
        q = (K.project(T_cam_hqcolor.apply(patches.points.reshape(-1, 3))).reshape(N, P, 2)
             - K.project(T_cam_hqcolor.apply(patches.centre))[:, None, :] + xy[:, None, :])
    h = patches.intensity.astype(np.float64)
    base = np.isfinite(h) & np.all(np.isfinite(q), axis=2)
    t = np.zeros((N, 2))
    ab = np.tile([1.0, 0.0], (N, 1))
    step = np.full(N, np.inf)
    for k in range(iterations):
        qq = q + t[:, None, :]
        I = _bilinear(L, qq).astype(np.float64)
        w = base & np.isfinite(I)
        Ix, Iy = _bilinear(gx, qq).astype(np.float64), _bilinear(gy, qq).astype(np.float64)
        hz, Iz = np.where(w, h, 0.0), np.where(w, I, 0.0)
        if k == 0:  # gain and bias first, at the matched position
            ab = _gain_bias(hz, Iz, w)
        r = np.where(w, Iz - ab[:, :1] * hz - ab[:, 1:], 0.0)
        J = np.stack([np.where(w, Ix, 0.0), np.where(w, Iy, 0.0), -hz, -w.astype(np.float64)], axis=2)  # (N, P, 4)
        A = np.einsum("npi,npj->nij", J, J) + 1e-9 * np.eye(4)
        g = np.einsum("npi,np->ni", J, r)
        try:
            d = -np.linalg.solve(A, g[..., None])[..., 0]
        except np.linalg.LinAlgError:
            d = np.zeros((N, 4))
        d = np.where(np.isfinite(d), d, 0.0)
        dt = np.clip(d[:, :2], -1.0, 1.0)
        t += dt
        ab += d[:, 2:]
        step = np.linalg.norm(dt, axis=1)
        if step.max() < 1e-3:
            break
    qq = q + t[:, None, :]
    I = _bilinear(L, qq).astype(np.float64)
    w = base & np.isfinite(I)
    ncc = _ncc(np.where(w, h, 0.0), np.where(w, I, 0.0), w)
    ok = (w.sum(axis=1) >= min_valid * P) & (np.linalg.norm(t, axis=1) <= max_px) & (step < 0.01) & (ncc >= min_ncc)
    return np.where(ok[:, None], t, 0.0), ok


def _gain_bias(h: np.ndarray, I: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Per row, ``(a, b)`` of the least-squares ``I = a h + b`` over the ``w`` pixels: ``(N, 2)``."""
    n = np.maximum(w.sum(axis=1), 1)
    mh, mI = h.sum(axis=1) / n, I.sum(axis=1) / n
    dh = np.where(w, h - mh[:, None], 0.0)
    a = (dh * np.where(w, I - mI[:, None], 0.0)).sum(axis=1) / np.maximum((dh * dh).sum(axis=1), 1e-9)
    return np.stack([a, mI - a * mh], axis=1)


def _ncc(h: np.ndarray, I: np.ndarray, w: np.ndarray) -> np.ndarray:
    n = np.maximum(w.sum(axis=1), 1)
    dh = np.where(w, h - (h.sum(axis=1) / n)[:, None], 0.0)
    dI = np.where(w, I - (I.sum(axis=1) / n)[:, None], 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (dh * dI).sum(axis=1) / np.sqrt((dh * dh).sum(axis=1) * (dI * dI).sum(axis=1))
