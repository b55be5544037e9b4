"""Depth warping: vectorised == per-pixel loop, and against an analytic ray-cast truth."""
import numpy as np
import pytest

from align.warp import DepthWarper, warp_depth, warp_depth_loop, warp_depth_naive_loop
from capture.camera import Intrinsics, Transform
from tests.align.scene import Plane, Rect, Sphere, cast, look_at, room


def _rig(scale=1.0, distortion=True):
    Kh = Intrinsics(512, 424, 365.0, 365.0, 255.5, 211.5, "opencv" if distortion else "none",
                    (0.09, -0.27, 0.001, -0.002, 0.09) if distortion else ())
    Kl = Intrinsics(640, 480, 600.0, 600.0, 319.5, 239.5, "opencv" if distortion else "none",
                    (0.03, -0.06, 0.001, -0.001, 0.0) if distortion else ())
    if scale != 1:
        Kh, Kl = Kh.scaled(round(512 * scale), round(424 * scale)), Kl.scaled(round(640 * scale), round(480 * scale))
    T_world_lq = look_at((0.0, 0, 0), (0.1, 0.1, 4))
    T_lq_hq = Transform.from_rotvec([0.01, -0.03, 0.005], [0.125, 0.01, -0.006])
    return Kh, Kl, T_lq_hq, T_lq_hq.inverse() @ T_world_lq, T_world_lq


def _truth(K, T_cam_world, shapes):
    depth, P, which = cast(K, T_cam_world, shapes)
    return depth, P, which


def _surface_distance(P, shape):
    """Distance of points (N, 3) to a shape (plane/rect plane/sphere surface), metres."""
    if isinstance(shape, Sphere):
        return np.abs(np.linalg.norm(P - np.asarray(shape.centre), axis=1) - shape.radius)
    if isinstance(shape, Rect):
        n = np.cross(shape.half_u, shape.half_v)
        return np.abs((P - np.asarray(shape.centre)) @ (n / np.linalg.norm(n)))
    n = np.asarray(shape.normal, float)
    return np.abs((P - np.asarray(shape.point)) @ (n / np.linalg.norm(n)))


@pytest.mark.parametrize("engine", ["numpy", "numba"])
@pytest.mark.parametrize("footprint,edge_reach", [(None, 0.5), (4, 0.5), (None, 0.0)])
def test_vectorised_equals_loop_reference(footprint, edge_reach, engine):
    # small cameras (fast loop), distortion on both, a noisy source with holes and a flying pixel
    Kh, Kl, T_lq_hq, T_hq_world, _ = _rig(scale=0.1)
    d, _, _ = _truth(Kh, T_hq_world, room())
    rng = np.random.default_rng(0)
    d = (d * (1 + 0.002 * rng.standard_normal(d.shape))).astype(np.float32)
    d[rng.random(d.shape) < 0.03] = np.nan
    fast = DepthWarper(Kh, Kl, T_lq_hq, footprint=footprint, engine=engine, edge_reach=edge_reach)(d)
    slow = warp_depth_loop(d, Kh, Kl, T_lq_hq, footprint=footprint, edge_reach=edge_reach)
    both = np.isfinite(fast) & np.isfinite(slow)
    assert np.isfinite(slow).sum() > 0.5 * slow.size
    # float32 against float64: a decision may flip on a threshold for a rare pixel
    assert (np.isfinite(fast) != np.isfinite(slow)).mean() < 0.005
    assert np.mean(np.abs(fast[both] - slow[both]) < 1e-4) > 0.995


def test_warp_matches_analytic_truth_and_never_bleeds():
    Kh, Kl, T_lq_hq, T_hq_world, T_lq_world = _rig(scale=0.5)
    shapes = room()
    dh, _, _ = _truth(Kh, T_hq_world, shapes)
    dl, Pl, which = _truth(Kl, T_lq_world, shapes)
    out = DepthWarper(Kh, Kl, T_lq_hq)(dh.astype(np.float32))
    ok = np.isfinite(out)
    err = np.abs(out - dl)[ok]
    assert np.median(err) < 1e-4  # exact on planes up to float32
    assert np.percentile(err, 95) < 1e-3
    # every LQ pixel whose surface the HQ camera also sees (and is not on a depth edge) has a value
    P = Pl.reshape(-1, 3)
    X_hq = T_hq_world.apply(P)
    uv = Kh.project(X_hq)
    iu, iv = np.rint(uv[:, 0]).astype(int), np.rint(uv[:, 1]).astype(int)
    inside = (iu >= 1) & (iu < Kh.width - 1) & (iv >= 1) & (iv < Kh.height - 1) & np.isfinite(dl).ravel()
    seen = np.zeros(P.shape[0], bool)
    seen[inside] = np.abs(dh[iv[inside], iu[inside]] - X_hq[inside, 2]) < 0.01 * X_hq[inside, 2]
    from scipy.ndimage import maximum_filter, minimum_filter
    smooth = (maximum_filter(dl, 5) - minimum_filter(dl, 5) < 0.05 * dl).ravel()
    target = seen & smooth
    assert target.sum() > 0.5 * dl.size
    assert ok.ravel()[target].mean() > 0.999
    # no bleeding: every warped value lies on a surface visible in the pixel's 3x3 neighbourhood
    rays = Kl.ray_grid()
    Pw = T_lq_world.inverse().apply(rays * np.where(ok, out, 0)[..., None])
    H, W = dl.shape
    pad = np.pad(which, 1, constant_values=-1)
    best = np.full((H, W), np.inf)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            nb = pad[1 + dy:1 + dy + H, 1 + dx:1 + dx + W]
            for s_i, shape in enumerate(shapes):
                m = ok & (nb == s_i)
                if m.any():
                    best[m] = np.minimum(best[m], _surface_distance(Pw[m], shape))
    # a mix of two surfaces would lie tens of cm off both; beyond the last sample of a steep
    # surface (the floor seen at a grazing angle) the value is held: up to ~1 cm off its plane
    assert np.all(best[ok] < 0.02), np.sort(best[ok])[-5:]
    assert np.mean(best[ok] < 0.001) > 0.98  # the rest: a one-pixel band along silhouettes


def test_nearest_surface_wins_and_flying_pixels_are_dropped():
    K = Intrinsics(120, 90, 100.0, 100.0, 59.5, 44.5)
    T = Transform.from_rt(np.eye(3), [0.2, 0.0, 0.0])  # large baseline: strong parallax
    shapes = [Plane((0, 0, 5.0), (0, 0, 1)), Rect((0.0, 0.0, 1.5), (0.2, 0, 0), (0, 0.2, 0))]
    d, _, _ = cast(K, Transform.identity(), shapes)
    d = d.astype(np.float32)
    truth, _, _ = cast(K, T, shapes)
    # a mixed (ToF flying) pixel half way between the slab and the wall on the slab's edge row
    rows, cols = np.nonzero(np.abs(d - 1.5) < 0.01)
    fly_r, fly_c = rows[len(rows) // 2], cols.max() + 1
    d[fly_r, fly_c] = 3.25
    out = warp_depth(d, K, K, T)
    from scipy.ndimage import maximum_filter
    slab = np.abs(truth - 1.5) < 0.01
    slab_inner = slab & (maximum_filter(truth, 3) < 1.51)
    assert slab_inner.sum() > 400
    assert np.nanmax(np.abs(out[slab_inner] - 1.5)) < 1e-3  # the slab occludes the wall
    # on the silhouette (where the true edge lies between two source samples) a pixel may get
    # either surface, never anything else; the mixed value appears nowhere
    ok = np.isfinite(out)
    near = np.zeros_like(ok)
    pad = np.pad(truth, 1, constant_values=np.nan)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            near |= np.abs(out - pad[1 + dy:1 + dy + 90, 1 + dx:1 + dx + 120]) < 1e-3
    assert np.all(near[ok])
    assert not np.any(np.abs(out - 3.25) < 0.3)


def test_identity_is_identity_and_bad_shape_raises():
    K = Intrinsics(64, 48, 60.0, 60.0, 31.5, 23.5)
    d = np.full((48, 64), 2.0, np.float32)
    d[10:20, 10:30] = 1.0
    out = warp_depth(d, K, K, Transform.identity())
    np.testing.assert_allclose(out, d, rtol=1e-6)
    with pytest.raises(ValueError, match="64x48"):
        warp_depth(np.zeros((10, 10), np.float32), K, K, Transform.identity())


def test_naive_loop_agrees_where_it_has_values():
    K = Intrinsics(40, 30, 40.0, 40.0, 19.5, 14.5)
    T = Transform.from_rotvec([0.01, 0.02, 0.0], [0.05, 0.03, 0.0])
    d, _, _ = cast(K, Transform.identity(), [Plane((0, 0, 2.0), (0, 0.3, 1))])
    naive = warp_depth_naive_loop(d.astype(np.float32), K, K, T)
    good = warp_depth(d.astype(np.float32), K, K, T)
    both = np.isfinite(naive) & np.isfinite(good)
    assert both.sum() > 500
    # the naive splat is off by up to half a pixel of depth gradient, the warp is exact
    truth, _, _ = cast(K, T, [Plane((0, 0, 2.0), (0, 0.3, 1))])
    inner = (slice(3, -3), slice(3, -3))  # the source image's border is an edge: values held there
    assert np.nanmax(np.abs(good - truth)[inner]) < 1e-4
    assert np.nanmax(np.abs(naive - truth)[inner]) > 1e-3


def test_noise_is_carried_without_bias():
    # a noisy slanted wall: the warped values must scatter around the truth, not be pulled towards
    # the camera (as keeping the largest of several overlapping noisy inverse depths would)
    Kh, Kl, T_lq_hq, T_hq_world, T_lq_world = _rig(scale=0.5, distortion=False)
    shapes = [Plane((0, 0, 3.0), (0.3, 0.1, 1))]
    dh, _, _ = cast(Kh, T_hq_world, shapes)
    dl, _, _ = cast(Kl, T_lq_world, shapes)
    rng = np.random.default_rng(3)
    sigma = 0.004
    noisy = (dh + sigma * rng.standard_normal(dh.shape)).astype(np.float32)
    out = DepthWarper(Kh, Kl, T_lq_hq)(noisy)
    err = (out - dl)[np.isfinite(out) & np.isfinite(dl)]
    assert err.size > 0.5 * dl.size
    assert abs(np.median(err)) < 0.05 * sigma
    assert abs(np.mean(err)) < 0.05 * sigma
    assert np.median(np.abs(err)) < 0.75 * sigma  # ~0.67 sigma for Gaussian noise carried one to one


@pytest.mark.parametrize("edge_reach", [0.5, 0.0, 0.25])
def test_numba_and_numpy_engines_agree(edge_reach):
    Kh, Kl, T_lq_hq, T_hq_world, _ = _rig(scale=0.25)
    d, _, _ = _truth(Kh, T_hq_world, room())
    rng = np.random.default_rng(4)
    d = (d * (1 + 0.003 * rng.standard_normal(d.shape))).astype(np.float32)
    d[rng.random(d.shape) < 0.02] = np.nan
    a = DepthWarper(Kh, Kl, T_lq_hq, engine="numba", edge_reach=edge_reach)(d)
    b = DepthWarper(Kh, Kl, T_lq_hq, engine="numpy", edge_reach=edge_reach)(d)
    assert np.array_equal(np.isnan(a), np.isnan(b))
    assert np.nanmax(np.abs(a - b)) < 1e-6


def test_motion_moves_the_points_before_the_splat():
    # a slanted wall seen by the HQ camera, moved 8 cm along x and 5 cm away: warping it with that
    # displacement gives what a warp of the moved wall gives (analytic, ray-cast); no motion = plain warp
    Kh, Kl, T_lq_hq, T_hq_world, _ = _rig(scale=0.25, distortion=False)
    wall = Plane((0, 0, 3.0), (0.2, 0.1, 1))
    dh, _, _ = cast(Kh, T_hq_world, [wall])
    dh = dh.astype(np.float32)
    shift = np.array([0.08, 0.0, 0.05])
    moved = Plane(tuple(np.asarray(wall.point) + T_hq_world.inverse().R @ shift), wall.normal)
    dm, _, _ = cast(Kh, T_hq_world, [moved])
    W = DepthWarper(Kh, Kl, T_lq_hq)
    motion = np.broadcast_to(shift.astype(np.float32), dh.shape + (3,))
    a, b = W(dh, motion=motion), W(dm.astype(np.float32))
    both = np.isfinite(a) & np.isfinite(b)
    assert both.sum() > 0.3 * a.size
    assert np.max(np.abs(a - b)[both]) < 2e-3
    assert np.array_equal(W(dh, motion=np.zeros(dh.shape + (3,), np.float32)), W(dh), equal_nan=True)
    gone = motion.copy()
    gone[:, : dh.shape[1] // 2] = np.nan  # NaN displacement: the point is dropped
    c = W(dh, motion=gone)
    assert np.isfinite(c).sum() < 0.75 * np.isfinite(a).sum()


@pytest.mark.parametrize("engine", ["numpy", "numba", "loop"])
@pytest.mark.parametrize("scale,edge_reach", [(1.3, 0.0), (1.9, 0.0), (1.9, 0.5)])
def test_a_surface_ends_at_a_diagonal_silhouette(engine, scale, edge_reach):
    """A near plane whose samples end on the diagonal i + j = c over a far plane: the near samples cover
    the half-plane x + y <= c of the source grid. The near surface reaches at most ``edge_reach`` steps past
    its last samples along each axis (x + y < c + 2 edge_reach), never into the far surface's corner of a
    grid square whose diagonal sample is far (before the diagonal cut it reached x + y = c + 1.05 at 1.9x with
    edge_reach 0): there nothing lands but its own splat past the triangle, which fills nothing alone;
    and it still covers everything well inside."""
    Ks = Intrinsics(40, 40, 50.0, 50.0, 19.5, 19.5)
    W = int(40 * scale)
    Kd = Intrinsics(W, W, 50.0 * scale, 50.0 * scale, (W - 1) / 2 + 0.3, (W - 1) / 2 + 0.15)  # sub-pixel offset
    i, j = np.mgrid[0:40, 0:40]
    c = 39
    d = np.where(i + j <= c, 1.0, 2.0).astype(np.float32)
    if engine == "loop":
        out = warp_depth_loop(d, Ks, Kd, Transform.identity(), edge_reach=edge_reach)
    else:
        out = DepthWarper(Ks, Kd, Transform.identity(), engine=engine, edge_reach=edge_reach)(d)
    v, u = np.mgrid[0:W, 0:W]
    x = (u - Kd.cx) / scale + Ks.cx   # the destination pixel centre on the source grid (identity pose: affine)
    y = (v - Kd.cy) / scale + Ks.cy
    inner = (x > 1) & (y > 1) & (x < 38) & (y < 38)
    near = np.isclose(out, 1.0)
    assert near[inner & (x + y < c - 1)].all()
    assert np.isclose(out[inner & (x + y > c + 2)], 2.0).all()
    assert (x + y)[near & inner].max() < c + 2 * edge_reach + 1e-4


def test_cut_splats_take_part_in_the_z_test_but_fill_nothing_alone():
    """A splat past the triangle of a quadrant cut at the diagonal: where a farther surface's splat landed, the
    nearer one still wins (the far samples seen just past a silhouette stay hidden); where nothing else landed
    the pixel stays empty; where a nearer splat landed, that one wins."""
    from align.warp_splat import EMPTY_KEY, merge_cut, zkey

    def key(w):
        hi, prio, lo = zkey(w, 1)
        return np.array([(hi << 8 | prio) << 32 | (lo & 0xFFFFFFFF)], np.int64)[0]

    buf = np.array([EMPTY_KEY, key(0.5), key(2.0)], np.int64)
    cut = np.array([key(1.0), key(1.0), key(1.0)], np.int64)
    merge_cut(buf, cut)
    assert buf.tolist() == [EMPTY_KEY, key(1.0), key(2.0)]


@pytest.mark.parametrize("engine", ["numpy", "numba"])
def test_warp_with_map_is_the_warp_and_the_forward_map(engine):
    """One forward projection for both (the ``footprint`` edge rules need both): bit for bit what ``warp`` and
    ``forward_map`` give apart, with and without motion, with a lens."""
    Kh, Kl, T_lq_hq, T_hq_world, _ = _rig(scale=0.25)
    dh = cast(Kh, T_hq_world, room())[0].astype(np.float32)
    dh[5:9, 10:30] = np.nan
    W = DepthWarper(Kh, Kl, T_lq_hq, engine=engine)
    motion = np.random.default_rng(0).normal(0, 0.02, dh.shape + (3,)).astype(np.float32)
    for m in (None, motion):
        out, fmap = W.warp_with_map(dh, motion=m)
        assert np.array_equal(out, W.warp(dh, motion=m), equal_nan=True)
        for a, b in zip(fmap, W.forward_map(dh, motion=m)):
            assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True)
