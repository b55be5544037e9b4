"""align.motion: the reference at the LQ instant from the two HQ frames around it (issue 12).

Against independent references: images drawn by formula (an occluder whose edges move at
constant velocity, a surface whose depth changes linearly), and the simulator's truth on tiny
sessions whose frames fall 7 ms or 0 ms apart (``--frame-phase-ms``)."""
from __future__ import annotations

import numpy as np
import pytest

from align.errors import OptionError, WarpInputError
from align.motion import MotionReference, bracket, compensate_motion

H, W = 48, 120
BG, FG = 3.0, 1.5


def _scene(x0: float, width: float) -> np.ndarray:
    """Background at 3 m, an occluder at 1.5 m covering the pixel centres in ``(x0, x0 + width)``, rows 10-37."""
    z = np.full((H, W), BG, np.float32)
    xs = np.arange(W) + 0.5
    z[10:38, (xs > x0) & (xs < x0 + width)] = FG
    return z


@pytest.mark.parametrize("width, move", [(30.0, 12.0), (10.0, 8.0), (20.0, -16.0)])
@pytest.mark.parametrize("alpha", [0.2, 0.5, 0.75])
def test_moving_edges_land_where_they_are_at_the_lq_instant(width, move, alpha):
    """Occluders wide and narrow, moving either way: every pixel more than 2 px (the 1 px margin,
    half a pixel, the rays' rounding) from the true edges at the LQ instant is right; the plain
    warp (the nearer frame) is wrong on the pixels the edges swept since."""
    A, B = _scene(20.0, width), _scene(20.0 + move, width)
    truth = _scene(20.0 + alpha * move, width)
    r = compensate_motion(A, B, alpha)
    xs = np.arange(W) + 0.5
    x_edges = np.array([20.0, 20.0 + width]) + alpha * move
    near_edge = np.zeros((H, W), bool)
    near_edge[:, np.min(np.abs(xs[:, None] - x_edges[None, :]), axis=1) < 2.0] = True
    rows = slice(14, 34)  # away from the occluder's top and bottom (the search goes along 16 rays)
    wrong = ~np.isclose(r.depth, truth)
    assert not wrong[rows][~near_edge[rows]].any()
    assert r.n_masked == 0
    plain = A if alpha <= 0.5 else B
    swept = ~np.isclose(plain, truth)[rows] & ~near_edge[rows]
    assert swept.sum() >= 20 * (abs(move) * min(alpha, 1 - alpha) - 4)  # the plain warp was wrong there
    assert r.taken_other > 0


def test_what_neither_frame_saw_stays_wrong():
    """The limitation, measured: a limb that moves more than its width between the frames passes
    pixels that both frames saw as background; those stay background (and nothing else is wrong)."""
    A, B = _scene(20.0, 10.0), _scene(44.0, 10.0)
    truth = _scene(20.0 + 0.5 * 24.0, 10.0)  # pixels 32-41: background in both frames
    r = compensate_motion(A, B, 0.5)
    wrong = np.flatnonzero(~np.isclose(r.depth[24], truth[24]))
    assert set(wrong) <= set(range(30, 44))
    assert set(range(33, 41)) <= set(wrong)


def _direct_loop(A, B, alpha, own, max_motion_px, margin_px=1.0, mask_within_px=0.0):
    """The module docstring's rules 1-3 pixel by pixel, in plain Python (the first version of the
    search: every ray one step further, the nearest hit of the first step with one, ties by ray):
    ``(depth, masked)``."""
    import cv2

    from align.motion import ONE_SIDED_REL, RAYS

    f32 = np.float32
    theta = np.arange(RAYS) * (2 * np.pi / RAYS)
    steps = np.arange(1, int(max_motion_px) + 1)
    dy = np.rint(np.outer(np.sin(theta), steps)).astype(int)
    dx = np.rint(np.outer(np.cos(theta), steps)).astype(int)
    dd = np.hypot(dy, dx).astype(f32)
    h, w = A.shape
    plain = A if own == "a" else B
    out = plain.copy()
    with np.errstate(invalid="ignore"):
        agree = np.abs(B - A) <= np.fmin(A, B) * f32(0.05)
        band = np.isfinite(B - A) & ~agree
    out[agree] = ((B - A) * f32(alpha) + A)[agree]
    near_band = cv2.dilate(band.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    inside = lambda y, x: 0 <= y < h and 0 <= x < w  # noqa: E731
    for y, x in zip(*np.nonzero(band | (near_band & np.isfinite(plain) & np.isnan(B if own == "a" else A)))):
        a, b = A[y, x], B[y, x]
        mid = np.sqrt(a * b) if np.isfinite(a) and np.isfinite(b) else np.fmax(a, b) * f32(1 + ONE_SIDED_REL)
        if (a < mid) == (b < mid):
            out[y, x] = np.nan
            continue
        C = A if b < mid else B
        hits = []
        for s in range(steps.size):
            hits = [(dd[r, s], r) for r in range(RAYS) if all(inside(y + dy[r, t], x + dx[r, t]) for t in range(s + 1))
                    and C[y + dy[r, s], x + dx[r, s]] < mid]
            if hits:
                break
        far = np.inf
        if hits:
            opp = (min(hits)[1] + RAYS // 2) % RAYS
            for s in range(steps.size):
                qy, qx = y + dy[opp, s], x + dx[opp, s]
                if not inside(qy, qx):
                    break
                a_q, b_q = A[qy, qx], B[qy, qx]
                if not (a_q < mid) and not (b_q < mid) and not (np.isnan(a_q) and np.isnan(b_q)):
                    far = dd[opp, s]
                    break
        near = min(hits)[0] if hits else np.inf
        d_a, d_b = (near, far) if b < mid else (far, near)
        if not (np.isfinite(d_a) and np.isfinite(d_b)):
            out[y, x] = np.nan
            continue
        passed = f32(alpha) * ((d_a - f32(0.5)) + (d_b - f32(0.5))) - (d_a - f32(0.5))
        out[y, x] = np.nan if abs(passed) < mask_within_px else (b if passed > (margin_px if own == "a" else -margin_px)
                                                                  else a)
    return out, np.isfinite(plain) & np.isnan(out)


@pytest.mark.parametrize("alpha, own", [(0.3, "a"), (0.7, "b"), (0.45, "b")])
def test_compiled_passes_equal_a_direct_loop(alpha, own):
    """The compiled passes (tables, skipped repeats, one call for all pixels) give, bit for bit, what
    the rules give pixel by pixel: two blobs and a hole moving, noise on the background, edges at
    the image border; with and without ``mask_within_px``."""
    rng = np.random.default_rng(5)
    yy, xx = np.mgrid[0:40, 0:56].astype(np.float32)

    def frame(shift):
        z = (3.0 + 0.01 * rng.standard_normal((40, 56))).astype(np.float32)
        z[(yy - 20) ** 2 + (xx - 16 - shift) ** 2 < 60] = 1.4 + 0.002 * xx[(yy - 20) ** 2 + (xx - 16 - shift) ** 2 < 60]
        z[(yy > 28) & (np.abs(xx - 40 + shift) < 5)] = 2.0  # a limb through the bottom border, moving the other way
        z[3:7, int(30 + shift):int(34 + shift)] = np.nan
        return z

    A, B = frame(0.0), frame(5.0)
    for mask_within in (0.0, 1.5):
        r = compensate_motion(A, B, alpha, own=own, max_motion_px=9, mask_within_px=mask_within)
        depth, masked = _direct_loop(A, B, alpha, own, 9, mask_within_px=mask_within)
        assert np.array_equal(r.depth, depth, equal_nan=True)
        assert np.array_equal(r.masked, masked)
        assert r.crossed > 20
        assert r.taken_other > 0 or mask_within > 0  # the other frame's surface was taken somewhere


def test_one_surface_is_linear_in_time():
    """A surface in both frames: depth A + alpha (B - A), exactly (a wall moving 2 % closer)."""
    A = np.full((H, W), 2.0, np.float32) + np.linspace(0, 0.2, W, dtype=np.float32)
    B = A * np.float32(0.98)
    A[0, 0] = np.nan
    r = compensate_motion(A, B, 0.3)
    expect = A + np.float32(0.3) * (B - A)
    assert np.isnan(r.depth[0, 0]) is False or np.isfinite(B[0, 0])  # own frame a has no depth there
    np.testing.assert_array_equal(r.depth[1:], expect[1:])
    assert r.interpolated == H * W - 1 and r.crossed == 0


def test_alpha_at_a_frame_gives_that_frame():
    A, B = _scene(20.0, 30.0), _scene(32.0, 30.0)
    np.testing.assert_array_equal(compensate_motion(A, B, 0.0).depth, A)
    np.testing.assert_array_equal(compensate_motion(A, B, 1.0).depth, B)


def test_own_frame_holes_stay_holes_and_far_edges_are_masked():
    """Nothing is invented where the own frame has no depth; an edge farther than max_motion_px is
    not decided: masked (NaN) and counted."""
    A, B = _scene(20.0, 30.0), _scene(32.0, 30.0)
    A[20:24, 60:70] = np.nan
    r = compensate_motion(A, B, 0.25)
    assert np.isnan(r.depth[20:24, 60:70]).all()
    r = compensate_motion(_scene(10.0, 20.0), _scene(70.0, 20.0), 0.5, max_motion_px=8)
    assert r.n_masked > 0 and np.isnan(r.depth[r.masked]).all()
    assert r.masked.sum() == (np.isfinite(_scene(10.0, 20.0)) & ~np.isfinite(r.depth)).sum()


def test_bad_inputs():
    A = _scene(20.0, 30.0)
    with pytest.raises(WarpInputError, match="one shape"):
        compensate_motion(A, A[:-1], 0.5)
    for kw in (dict(alpha=1.5), dict(alpha=0.5, own="c"), dict(alpha=0.5, edge_rel=0), dict(alpha=0.5, max_motion_px=0),
               dict(alpha=0.5, margin_px=-1)):
        with pytest.raises(OptionError):
            compensate_motion(A, A, **kw)


def test_bracket():
    t = np.array([0, 33_333, 66_667, 133_333], np.int64)  # frame 3 follows a dropped frame
    assert bracket(t, 1, 7000) == (1, 2, pytest.approx(7000 / 33_334))
    assert bracket(t, 1, -7000) == (0, 1, pytest.approx(1 - 7000 / 33_333))
    assert bracket(t, 0, -7000) is None and bracket(t, 2, 7000) is None  # no neighbour / a gap of two periods
    assert bracket(t, 1, 0) is None


def test_reference_keeps_plain_warp_of_close_pairs_and_warps_each_frame_once():
    frames = {i: _scene(20.0 + 4 * i, 30.0) for i in range(6)}
    calls = []

    def warped(i):
        calls.append(i)
        return frames[i]

    t = np.arange(6, dtype=np.int64) * 33_333
    ref = MotionReference(warped, t, min_dt_us=1000)
    out, pm = ref(2, 500.0)
    assert out is frames[2] and pm.frames is None and pm.reason == "frames fall together"
    for i in range(5):
        out, pm = ref(i, 7000.0)
        assert pm.frames == (i, i + 1) and pm.alpha == pytest.approx(0.21, abs=0.01)
    assert sorted(calls) == list(range(6))  # each HQ frame warped once while the pairs come in order
    off = MotionReference(warped, t, enabled=False)
    out, pm = off(3, 7000.0)
    assert out is frames[3] and pm.reason == "off"


@pytest.fixture(scope="module")
def phased(tmp_path_factory):
    """Small people sessions (half scale, 1 s, seed 11) whose frames fall 0 and 7 ms apart."""
    from capture.sim import simulate

    root = tmp_path_factory.mktemp("phase")
    for ms in (0, 7):
        simulate(root / f"p{ms}", rig="lq-hq", scene="people", seconds=1.0, seed=11, scale=0.5, progress=False,
                 frame_phase_us=ms * 1000)
    return {ms: root / f"p{ms}" for ms in (0, 7)}


def _reference_mae(root, *, motion: bool) -> tuple[float, float, float]:
    """MAE (mm) of the references of every LQ frame against the LQ truth on the region of interest
    (as align computes it), the reference built as align builds it (truth's shift and T_lq_hq, align's
    edge rule); the median time apart (ms) and the share of ROI pixels the motion compensation masked."""
    from align.pipeline import pair_setup
    from align.reference_edges import EdgeRule
    from align.roi import background_depth, foreground_mask
    from align.warp import DepthWarper
    from capture.session import open_session
    from capture.truth import read_truth

    sess, tr = open_session(root), read_truth(root)
    setup = pair_setup(sess, lq="lq", hq="hq")
    rule = EdgeRule.named("strict")
    warper = DepthWarper(setup.K_hq, setup.K_lq, tr.T_lq_hq, edge_reach=rule.edge_reach)
    ref = MotionReference(lambda i: warper(sess.read_depth("hq", int(setup.f_hq[i]))), setup.t_hq, enabled=motion)
    rows = []
    for j in range(2, setup.f_lq.size - 2):
        s = setup.t_lq[j] - tr.time_shift_at_us(setup.t_lq[j])
        i = int(np.argmin(np.abs(setup.t_hq - s)))
        r, pm = ref(i, float(s - setup.t_hq[i]))
        rows.append((rule.apply(r)[0], pm, tr.depth("lq", int(setup.f_lq[j])), sess.read_depth("lq", int(setup.f_lq[j]))))
    bg = background_depth(np.stack([np.where(np.isfinite(r), r, lq) for r, _, _, lq in rows]))
    err, n_masked, n = [], 0, 0
    for r, pm, truth, lq in rows:
        roi = foreground_mask(np.where(np.isfinite(r), r, lq), bg) & np.isfinite(truth)
        err.append(np.abs(r - truth)[roi & np.isfinite(r)])
        n += int(roi.sum())
        n_masked += 0 if pm.masked_map is None else int((pm.masked_map & roi).sum())
    apart = np.median([abs(pm.dt_us) for _, pm, _, _ in rows]) / 1000
    return 1000 * float(np.concatenate(err).mean()), float(apart), n_masked / n


def test_reference_at_the_lq_instant_against_truth(phased):
    """Issue 12 at small scale: frames 7 ms apart put the plain reference's MAE on the region of interest
    far above that of frames that fall together (here 10.1 against 2.8 mm); carried to the LQ instant it
    falls back part of the way (8.0 mm, 2.1 % of the ROI masked). At full scale the compensation recovers
    about half of the gap (notes of issue 12, perf/reference_motion.py); the rest is what neither HQ frame saw."""
    plain0, apart0, _ = _reference_mae(phased[0], motion=False)
    plain7, apart7, _ = _reference_mae(phased[7], motion=False)
    moved7, _, masked = _reference_mae(phased[7], motion=True)
    assert apart0 < 0.5 and 6.5 < apart7 < 7.5
    assert plain7 > 2 * plain0
    assert moved7 < plain7 - 0.2 * (plain7 - plain0), (plain0, plain7, moved7)
    assert masked < 0.03
