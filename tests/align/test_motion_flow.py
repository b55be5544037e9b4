"""Scene-flow motion (align.motion_flow): the HQ frame's points moved along the HQ colour images' optical
flow land where an analytic ray caster puts the moving objects at the LQ instant."""
import cv2
import numpy as np
import pytest

from align.errors import WarpInputError
from align.motion import MotionReference
from align.motion_flow import ColorFlow, FlowMotion, SceneFlow, flow_image
from align.warp import DepthWarper
from capture.camera import Intrinsics, Transform
from tests.align.scene import cast, room, texture
from tests.align.test_warp import _rig

MOVING = (3, 4)  # room(): the person slab and the ball move with person_at


def _frames(p0, v, alpha):
    """HQ depth and colour at t = 0 and one period later, the LQ truth and a synchronous HQ frame at ``alpha``."""
    Kh, Kl, T_lq_hq, T_hq_world, T_lq_world = _rig(scale=0.5, distortion=False)
    Kc = Intrinsics(480, 270, 265.0, 265.0, 239.5, 134.5)
    T_color_depth = Transform.from_rotvec([0.0, 0.004, 0.0], [-0.052, 0.001, 0.0])
    at = lambda s: tuple(np.add(p0, np.multiply(s, v)))  # noqa: E731

    def hq(s):
        d = cast(Kh, T_hq_world, room(person_at=at(s)))[0].astype(np.float32)
        _, P, which = cast(Kc, T_color_depth @ T_hq_world, room(person_at=at(s)))
        moving = np.isin(which, MOVING)[..., None]
        return d, texture(np.where(moving, P - np.multiply(s, v), P))  # the texture moves with its object

    (da, ca), (db, cb) = hq(0.0), hq(1.0)
    truth, _, which = cast(Kl, T_lq_world, room(person_at=at(alpha)))
    roi = cv2.dilate(np.isin(which, MOVING).astype(np.uint8), np.ones((11, 11), np.uint8)) > 0
    return dict(Kh=Kh, Kl=Kl, Kc=Kc, T_lq_hq=T_lq_hq, T_color_depth=T_color_depth, depth=(da, db), color=(ca, cb),
                truth=truth.astype(np.float32), roi=roi, sync=hq(alpha)[0])


def _mae(ref, truth, roi):
    ok = roi & np.isfinite(ref) & np.isfinite(truth)
    return float(np.abs(ref - truth)[ok].mean() * 1000)


@pytest.mark.parametrize("v", [(0.07, 0.0, 0.0), (-0.05, 0.01, -0.04)])
def test_moved_points_land_where_the_objects_are_at_the_lq_instant(v):
    alpha = 0.25  # 8 ms after the HQ frame at 30 fps
    f = _frames((0.0, 0.2, 2.2), v, alpha)
    warper = DepthWarper(f["Kh"], f["Kl"], f["T_lq_hq"], edge_reach=0.0)
    flow = FlowMotion(lambda i: f["depth"][i], lambda i: f["color"][i], warper,
                      SceneFlow(f["Kh"], f["Kc"], f["T_color_depth"]))
    plain = _mae(warper(f["depth"][0]), f["truth"], f["roi"])
    sync = _mae(warper(f["sync"]), f["truth"], f["roi"])
    moved = _mae(flow(0, 1, alpha), f["truth"], f["roi"])
    back = _mae(flow(1, 0, 1 - alpha), f["truth"], f["roi"])  # from the later frame, backwards
    assert plain > sync + 5  # the motion's error is there
    # more than half of it removed (the edge model, align.motion, removes a fifth to a half; on the
    # simulator's walking people the flow removes ~90 %: perf/reference_motion.py)
    assert moved < sync + 0.5 * (plain - sync), (plain, sync, moved)
    plain_b = _mae(warper(f["depth"][1]), f["truth"], f["roi"])
    assert back < sync + 0.5 * (plain_b - sync), (plain_b, sync, back)


def test_motion_reference_uses_the_flow_and_falls_back_to_edges_without_colour():
    f = _frames((0.0, 0.2, 2.2), (0.07, 0.0, 0.0), 0.25)
    warper = DepthWarper(f["Kh"], f["Kl"], f["T_lq_hq"], edge_reach=0.0)
    sf = SceneFlow(f["Kh"], f["Kc"], f["T_color_depth"])
    t_hq = np.array([0, 40000])  # alpha = 10000 / 40000 = 0.25 exactly
    with_color = MotionReference(lambda i: warper(f["depth"][i]), t_hq,
                                 moved=FlowMotion(lambda i: f["depth"][i], lambda i: f["color"][i], warper, sf))
    ref, pm = with_color(0, 10000.0)
    assert pm.model == "scene flow" and pm.frames == (0, 1)
    assert np.array_equal(ref, FlowMotion(lambda i: f["depth"][i], lambda i: f["color"][i], warper, sf)(0, 1, 0.25),
                          equal_nan=True)
    without = MotionReference(lambda i: warper(f["depth"][i]), t_hq,
                              moved=FlowMotion(lambda i: f["depth"][i], lambda i: None, warper, sf))
    edges = MotionReference(lambda i: warper(f["depth"][i]), t_hq)
    (r1, pm1), (r2, _) = without(0, 10000.0), edges(0, 10000.0)
    assert pm1.model == "edges" and np.array_equal(r1, r2, equal_nan=True)


def test_scene_flow_of_a_still_scene_is_zero_and_bad_sizes_fail():
    f = _frames((0.0, 0.2, 2.2), (0.0, 0.0, 0.0), 0.5)
    sf = SceneFlow(f["Kh"], f["Kc"], f["T_color_depth"])
    g = flow_image(f["color"][0])
    m, trusted = sf.motion(f["depth"][0], f["depth"][1], ColorFlow()(g, g))
    assert trusted.mean() > 0.8 and np.abs(m).max() < 1e-4
    with pytest.raises(WarpInputError):
        sf.motion(f["depth"][0][:-1], f["depth"][1], ColorFlow()(g, g))
