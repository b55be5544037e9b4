"""align.rig_refine against independent references: a direct loop, Monte Carlo, an analytic room
seen by four cameras whose poses are known exactly (tests/align/scene.py's ray caster)."""
from __future__ import annotations

import numpy as np
import pytest

from align.rig_refine import (PairRegistration, point_to_plane_covariance, refine_rig, static_cloud, static_depth,
                              _drop_failed)
from capture.camera import Intrinsics, Transform
from tests.align.scene import Plane, Rect, Sphere, cast, look_at

K = Intrinsics(160, 120, 150.0, 150.0, 79.5, 59.5)
EYES = [(-0.6, 0.0, 0.0), (0.6, 0.0, 0.0), (-0.6, -1.0, 0.0), (0.6, -1.0, 0.0)]  # an H-stand, y down
VIEWS = [f"view{i}" for i in range(4)]


def _rig_truth() -> dict[str, Transform]:
    T_cw = [look_at(e, (0.0, 0.3, 3.2)) for e in EYES]
    return {v: T_cw[0] @ T_cw[i].inverse() for i, v in enumerate(VIEWS)}, T_cw


def _room(x_person: float):
    """Back wall, floor, a side wall, a static cabinet (two faces) and three balls; a person slab at ``x_person``."""
    return [Plane((0, 0, 4.5), (0, 0, 1)), Plane((0, 1.2, 0), (0, 1, 0)), Plane((-2.0, 0, 0), (1, 0, 0)),
            Rect((1.2, 0.6, 3.8), (0.4, 0, -0.3), (0, 0.6, 0)), Rect((0.8, 0.6, 3.8), (0.0, 0, 0.3), (0, 0.6, 0)),
            Sphere((-0.9, 0.7, 3.4), 0.45), Sphere((0.9, 0.8, 2.9), 0.4), Sphere((0.0, 0.9, 4.0), 0.3),
            Rect((x_person, 0.3, 2.4), (0.15, 0, 0.03), (0, 0.5, 0))]


def _frames(T_cam_world: Transform, rng, n=8, noise_m=0.001):
    """A person slab walking across the room; depth with z^2-scaled noise, a few holes."""
    out = []
    for k in range(n):
        d, _, _ = cast(K, T_cam_world, _room(-0.4 + 0.1 * k))
        d = d + rng.normal(0, 1, d.shape) * noise_m * d ** 2
        d[rng.random(d.shape) < 0.02] = np.nan
        out.append(d.astype(np.float32))
    return np.stack(out)


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(0)
    truth, T_cw = _rig_truth()
    clouds = {v: static_cloud(_frames(T_cw[i], rng), K) for i, v in enumerate(VIEWS)}
    return truth, T_cw, clouds


def test_static_depth_against_a_direct_loop():
    rng = np.random.default_rng(1)
    D = rng.uniform(1.0, 3.0, (10, 6, 7)).astype(np.float32)
    D[:, 0, 0] = np.nan              # never measured
    D[:3, 1, 1] = np.nan             # measured in 7 of 10 frames: below 80 %
    D[:, 2, 2] = 2.0
    D[:2, 2, 2] = 1.0                # a person in 2 of 10 frames: moved
    D[:, 3, 3] = 2.0
    D[0, 3, 3] = 1.0                 # in 1 of 10: still static, the median ignores it
    med, static = static_depth(D)
    for y in range(6):
        for x in range(7):
            col = D[:, y, x]
            ok = col[np.isfinite(col)]
            if ok.size == 0:
                assert not static[y, x]
                continue
            m = np.median(ok)
            moved = sum(abs(c - m) > max(0.03, 0.01 * m * m) for c in ok)
            want = ok.size >= 8 and moved <= 1
            assert static[y, x] == want, (y, x)
            assert (med[y, x] == pytest.approx(m)) if want else np.isnan(med[y, x])
    assert not static[2, 2] and static[3, 3] and med[3, 3] == 2.0


def test_point_to_plane_covariance_against_monte_carlo():
    """Independent points (effective_points = N): the formula's covariance is the spread of the
    linearised point-to-plane solution over noise draws."""
    rng = np.random.default_rng(2)
    n = np.concatenate([np.tile([0, 0, 1.0], (200, 1)), np.tile([0, 1.0, 0], (200, 1)), np.tile([1.0, 0, 0], (200, 1))])
    q = rng.uniform(-1, 1, (600, 3)) * (1 - np.abs(n)) + n * 2.0
    sigma = 0.004
    est = []
    J = np.concatenate([np.cross(q, n), n], axis=1)
    for _ in range(400):
        p = q + n * rng.normal(0, sigma, (600, 1))
        r = np.einsum("ij,ij->i", n, p - q)
        est.append(np.linalg.lstsq(J, -r, rcond=None)[0])
    emp = np.cov(np.array(est).T)
    p = q + n * rng.normal(0, sigma, (600, 1))
    cov, rms = point_to_plane_covariance(p, q, n, effective_points=600)
    assert rms == pytest.approx(sigma, rel=0.15)
    ratio = np.diag(cov) / np.diag(emp)
    assert np.all((ratio > 0.7) & (ratio < 1.4)), ratio
    # fewer effective points: the same shape, larger
    cov100, _ = point_to_plane_covariance(p, q, n, effective_points=100)
    assert np.allclose(cov100, cov * 6)


def test_static_cloud_leaves_the_walking_person_out(scene):
    truth, T_cw, clouds = scene
    P = T_cw[0].inverse().apply(clouds["view0"].points)  # world
    walked = (np.abs(P[:, 2] - 2.4) < 0.15) & (P[:, 0] > -0.6) & (P[:, 0] < 0.5) & (np.abs(P[:, 1] - 0.3) < 0.55)
    assert walked.sum() < 0.002 * len(P), walked.sum()
    assert len(P) > 2000
    assert np.allclose(np.linalg.norm(clouds["view0"].normals, axis=1), 1.0, atol=1e-6)


def _perturb(T: Transform, rng, t_m, r_deg) -> Transform:
    ax = rng.normal(size=3)
    d = Transform.from_rotvec(ax / np.linalg.norm(ax) * np.radians(r_deg), rng.normal(size=3) / np.sqrt(3) * t_m)
    return d @ T


def test_refine_rig_recovers_the_rig_within_its_sd_and_flags_a_wrong_feature_fit(scene):
    truth, _, clouds = scene
    rng = np.random.default_rng(3)
    init = {v: truth[v] if v == "view0" else _perturb(truth[v], rng, 0.05, 0.6) for v in VIEWS}
    cov = np.diag([np.radians(0.2) ** 2] * 3 + [0.01 ** 2] * 3)
    # view1's "feature fit" is 80 mm / 1 deg off with a claimed sd of ~10 mm / 0.2 deg per axis: it must be
    # flagged; view2's is the truth itself: it must not be
    wrong = _perturb(truth["view1"], rng, 0.08, 1.0)
    feats = [PairRegistration("view0", "view1", wrong, cov, 100, 0.5, float("nan"), kind="features"),
             PairRegistration("view0", "view2", truth["view2"], cov, 100, 0.5, float("nan"), kind="features")]
    r = refine_rig("view0", init, clouds, feature_edges=feats)
    assert len(r.used) == 6 and r.dof == 18
    for v in VIEWS[1:]:
        dt, dr = r.T_rig_sensor[v].error_to(truth[v])
        assert dt < 0.01 and dr < 0.2, (v, dt, dr)
        # within the stated uncertainty (3-D norm against sqrt(trace): chi with 3 dof, 99.9 % below 2.2x)
        assert dt < 2.2 * r.translation_std_m(v) and dr < 2.2 * r.rotation_std_deg(v), (v, dt, r.translation_std_m(v))
        # and not vacuous: the sds are small next to the 80 mm / 1 deg it started from
        assert r.translation_std_m(v) < 0.015 and r.rotation_std_deg(v) < 0.3
    assert r.feature_sigmas["view1"] > 4.7 and r.feature_sigmas["view2"] < 4.7
    assert any(w.startswith("view1: its feature fit") for w in r.notes)
    assert not any(w.startswith("view2") for w in r.notes)
    s = r.summary()  # a wrong feature fit is a note: the refined rig itself is consistent
    assert s["consistent"] is True and len(s["pairs"]) == 6 and s["feature_fit_sd_off"]["view1"] > 4.7


def _edge(a, b, truth, rng, cov, off_m=0.0):
    Z = truth[a].inverse() @ truth[b]
    noise = rng.multivariate_normal(np.zeros(6), cov)
    Z = Transform.from_rotvec(noise[:3], noise[3:] + np.array([off_m, 0, 0])) @ Z
    return PairRegistration(a, b, Z, cov, 5000, 0.005, 0.5)


def test_pose_graph_drops_a_failed_registration():
    """Hand-made pair measurements (no ICP): one pair 150 mm off is dropped and the rest agree."""
    truth, _ = _rig_truth()
    rng = np.random.default_rng(4)
    cov = np.diag([np.radians(0.05) ** 2] * 3 + [0.002 ** 2] * 3)
    pairs = [_edge(a, b, truth, rng, cov, off_m=0.15 if (a, b) == ("view1", "view2") else 0.0)
             for i, a in enumerate(VIEWS) for b in VIEWS[i + 1:]]
    kept, warnings = _drop_failed("view0", truth, pairs)
    assert [(p.a, p.b) for p in pairs if p not in kept] == [("view1", "view2")]
    assert warnings and warnings[0].startswith("view1-view2: depth registration dropped")
    clean = [_edge(a, b, truth, rng, cov) for i, a in enumerate(VIEWS) for b in VIEWS[i + 1:]]
    kept, warnings = _drop_failed("view0", truth, clean)
    assert len(kept) == 6 and not warnings
