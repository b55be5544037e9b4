"""The reference's edge rule: the occluded-side mask against a direct loop, and the strict rule against
an analytic ray-cast truth on a scene whose HQ depth carries time-of-flight mixed pixels."""
import numpy as np
import pytest

from align.errors import OptionError
from align.reference_edges import EdgeRule, occluded_side
from align.warp import DepthWarper
from tests.align.scene import cast, room
from tests.align.test_warp import _rig


def _occluded_side_loop(z, r, rel):
    H, W = z.shape
    out = np.zeros((H, W), bool)
    for i in range(H):
        for j in range(W):
            if not np.isfinite(z[i, j]):
                continue
            for di in range(-r, r + 1):
                for dj in range(-r, r + 1):
                    ii, jj = i + di, j + dj
                    # OpenCV's elliptic disc for radius r: the integer points of the ellipse
                    if 0 <= ii < H and 0 <= jj < W and _in_disc(di, dj, r) and np.isfinite(z[ii, jj]):
                        out[i, j] |= z[i, j] - z[ii, jj] > rel * z[ii, jj]
    return out


def _in_disc(di, dj, r):
    import cv2

    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    return bool(disc[di + r, dj + r])


@pytest.mark.parametrize("r", [1, 2])
def test_occluded_side_equals_a_direct_loop(r):
    rng = np.random.default_rng(r)
    z = rng.choice([1.0, 1.02, 2.0, 3.0], size=(14, 17)).astype(np.float32)
    z[rng.random(z.shape) < 0.15] = np.nan
    assert np.array_equal(occluded_side(z, radius_px=r, edge_rel=0.03), _occluded_side_loop(z, r, 0.03))


def test_rules_by_name_and_a_bad_name():
    assert EdgeRule.named("midpoint").apply(np.ones((3, 3), np.float32))[1].sum() == 0
    assert EdgeRule.named("strict").edge_reach == 0.0
    with pytest.raises(OptionError, match="reference edge rule"):
        EdgeRule.named("sharp")
    with pytest.raises(OptionError, match="edge reach"):
        K = _rig(scale=0.1)[0]
        DepthWarper(K, K, _rig(scale=0.1)[2], edge_reach=1.0)


def _mixed_pixels(d, rng, *, jump_m=0.1, fraction=0.5):
    """The simulator's time-of-flight mixed pixels: in the 3x3 band of every jump, a random mix of near and far."""
    from scipy.ndimage import maximum_filter, minimum_filter

    f = np.where(np.isfinite(d), d, 0)
    near, far = minimum_filter(np.where(f > 0, f, 99), 3), maximum_filter(f, 3)
    band = (f > 0) & (far - near > jump_m) & (rng.random(d.shape) < fraction)
    w = rng.random(d.shape)
    return np.where(band, w * near + (1 - w) * far, d).astype(np.float32)


def test_strict_rule_removes_most_large_errors_of_the_midpoint_warp():
    # analytic truth on both cameras (HQ 12.5 cm beside LQ, LQ 1.6x finer), HQ with mixed pixels
    Kh, Kl, T_lq_hq, T_hq_world, T_lq_world = _rig(scale=0.5, distortion=False)
    errors = {}
    for person in ((0.0, 0.2, 2.2), (-0.4, 0.1, 1.8), (0.5, 0.3, 2.6)):
        shapes = room(person_at=person)
        dh = _mixed_pixels(cast(Kh, T_hq_world, shapes)[0], np.random.default_rng(len(errors)))
        dl = cast(Kl, T_lq_world, shapes)[0]
        for name in ("midpoint", "strict"):
            rule = EdgeRule.named(name)
            ref, mask = rule.apply(DepthWarper(Kh, Kl, T_lq_hq, edge_reach=rule.edge_reach)(dh))
            ok = np.isfinite(ref) & np.isfinite(dl)
            e = np.abs(ref - dl)[ok]
            big, n, m = errors.get(name, (0, 0, 0))
            errors[name] = (big + int((e > 0.05).sum()), n + int(np.isfinite(dl).sum()), m + int(mask.sum()))
    big_mid, n, _ = errors["midpoint"]
    big_strict, _, masked = errors["strict"]
    assert big_mid > 0.001 * n  # the midpoint warp's edge errors exist on this scene
    assert big_strict < 0.3 * big_mid
    assert masked < 0.05 * n  # what the mask costs stays a thin band


@pytest.mark.parametrize("base", ["strict", "mixed"])
def test_fg_rules_mask_only_what_the_roi_scores_and_keep_its_errors(base):
    """``strict-fg``/``mixed-fg`` against their base rule on an analytic scene (a slab in front of a ball, both
    in front of the room; HQ with mixed pixels and noise; the LQ depth fattened at edges, as stereo does):
    the band is the base's where the reference is in front of the background and nothing elsewhere, so the
    ROI's errors against the ray-cast truth are the base's while far fewer ROI pixels are masked."""
    from scipy.ndimage import minimum_filter

    from align.pair_reference import PairReferences, ReferenceOptions
    from align.roi import foreground_mask, in_front
    from tests.align.scene import Sphere

    Kh, Kl, T_lq_hq, T_hq_world, T_lq_world = _rig(scale=0.5, distortion=False)
    acc = {}
    for s, person in enumerate(((0.0, 0.2, 2.2), (-0.4, 0.1, 1.8), (0.5, 0.3, 2.6))):
        shapes = room(person_at=person)[:4] + [Sphere((person[0] + 0.3, person[1] - 0.2, person[2] + 0.6), 0.25)]
        rng = np.random.default_rng(s)
        dh = _mixed_pixels(cast(Kh, T_hq_world, shapes)[0], rng)
        dh = (dh * (1 + 0.001 * rng.standard_normal(dh.shape))).astype(np.float32)
        dl = cast(Kl, T_lq_world, shapes)[0].astype(np.float32)
        bg = cast(Kl, T_lq_world, shapes[:3])[0].astype(np.float32)
        lq = minimum_filter(np.where(np.isfinite(dl), dl, 99), 5).astype(np.float32)  # foreground fattened by 2 px
        for name in (base, f"{base}-fg"):
            r = PairReferences(lambda i: dh, K_hq=Kh, K_lq=Kl, T_lq_hq=T_lq_hq, t_hq_us=np.array([0]), background=bg,
                               options=ReferenceOptions(reference_edges=name, motion=False))(0, 0.0)
            roi = foreground_mask(np.where(np.isfinite(r.depth), r.depth, lq), bg) & np.isfinite(dl)
            e = np.abs(r.depth - dl)[roi & np.isfinite(r.depth)]
            a = acc.setdefault(name, np.zeros(4))
            a += (int((e > 0.3).sum()), (e ** 2).sum(), e.size, int((r.edge_mask & roi).sum()))
            if name == "strict-fg":  # the band where the reference is in front of the background, by formula
                plain = DepthWarper(Kh, Kl, T_lq_hq, edge_reach=0.0)(dh)
                band = occluded_side(plain, radius_px=3) & in_front(plain, bg)
                assert np.array_equal(r.depth, np.where(band, np.float32(np.nan), plain), equal_nan=True)
                assert np.array_equal(r.edge_mask, band)
    full, fg = acc[base], acc[f"{base}-fg"]
    assert fg[0] <= full[0]  # no whole-jump error the base rule does not have
    assert np.sqrt(fg[1] / fg[2]) < 1.1 * np.sqrt(full[1] / full[2])
    assert fg[3] < 0.2 * full[3]  # far fewer ROI pixels masked (the base's band is mostly background the LQ fattens)


def test_footprint_occluders_equal_a_direct_loop():
    from align.reference_edges import MAX_OCCLUDER_PX, footprint_occluders

    Kh, Kl, T_lq_hq, _, _ = _rig(scale=0.1, distortion=False)
    rng = np.random.default_rng(7)
    hq = rng.choice([1.0, 1.5, 3.0], size=Kh.shape).astype(np.float32) * (1 + 0.01 * rng.random(Kh.shape)).astype(np.float32)
    hq[rng.random(hq.shape) < 0.2] = np.nan
    warper = DepthWarper(Kh, Kl, T_lq_hq, edge_reach=0.0)
    u, v, w, valid = warper.forward_map(hq)
    for reach, edges_only in ((1.0, False), (2.5, False), (2.5, True)):
        got = footprint_occluders(warper, hq, reach=reach, edges_only=edges_only)
        R = int(min(max(round(0.5 * reach * Kl.fx / Kh.fx), 1), MAX_OCCLUDER_PX))
        want = np.full(Kl.shape, np.inf, np.float32)
        for r, c in zip(*np.nonzero(valid & np.isfinite(hq))):
            if edges_only:  # a 3x3 neighbour of a sample with a 3x3 neighbour missing or 3 % farther
                window = [(rr, cc) for rr in range(r - 1, r + 2) for cc in range(c - 1, c + 2)
                          if 0 <= rr < hq.shape[0] and 0 <= cc < hq.shape[1] and np.isfinite(hq[rr, cc])]
                at_edge = [(rr, cc) for rr, cc in window
                           if any(not np.isfinite(hq[y, x]) or hq[y, x] - hq[rr, cc] > 0.03 * hq[rr, cc]
                                  for y in range(max(rr - 1, 0), min(rr + 2, hq.shape[0]))
                                  for x in range(max(cc - 1, 0), min(cc + 2, hq.shape[1])))]
                if not at_edge:
                    continue
            cu, cv = int(np.round(u[r, c])), int(np.round(v[r, c]))
            for y in range(cv - R, cv + R + 1):
                for x in range(cu - R, cu + R + 1):
                    if 0 <= x < Kl.width and 0 <= y < Kl.height and 0 <= cu < Kl.width and 0 <= cv < Kl.height:
                        want[y, x] = min(want[y, x], np.float32(1) / w[r, c])
        assert np.isfinite(got).mean() > 0.3
        np.testing.assert_allclose(got, want, rtol=1e-6)


def _near_side_mixes(d, rng, *, width):
    """The near side's last ``width`` HQ samples of every jump (> 0.1 m) replaced by random mixes of near and far
    (a coarse ToF sensor at a grazing silhouette): the warp cannot link them into the near surface."""
    from scipy.ndimage import maximum_filter, minimum_filter

    f = np.where(np.isfinite(d), d, 0)
    near, far = minimum_filter(np.where(f > 0, f, 99), 2 * width + 1), maximum_filter(f, 2 * width + 1)
    band = (f > 0) & (far - near > 0.1) & (np.abs(f - near) < 0.03 * near)
    w = rng.uniform(0.2, 0.8, d.shape)
    return np.where(band, w * near + (1 - w) * far, d).astype(np.float32)


def _slab_scenes(seed0):
    """Three analytic scenes (a slab 0.7 m in front of two boards, all in front of the room), each with the rig:
    yields ``(rng, HQ depth (truth), LQ truth, LQ background, rig)``, ``rng`` seeded ``seed0 + scene``."""
    from tests.align.scene import Rect

    rig = _rig(scale=0.5, distortion=False)
    Kh, Kl, _, T_hq_world, T_lq_world = rig
    for s, (px, py, pz) in enumerate(((0.0, 0.2, 2.2), (-0.4, 0.1, 1.8), (0.5, 0.3, 2.6))):
        shapes = room(person_at=(px, py, pz))[:4] + [Rect((px + dx, py, pz + 0.7), (0.3, 0, 0), (0, 0.6, 0))
                                                     for dx in (-0.3, 0.3)]
        yield (np.random.default_rng(seed0 + s), cast(Kh, T_hq_world, shapes)[0],
               cast(Kl, T_lq_world, shapes)[0].astype(np.float32), cast(Kl, T_lq_world, shapes[:3])[0].astype(np.float32),
               rig)


def _reference_and_counts(dh, name, *, rig, dl, bg, lq, acc):
    """The rule ``name``'s reference of HQ depth ``dh``; adds (ROI pixels > 0.3 m off, masked ROI pixels, ROI
    pixels) to ``acc[name]``."""
    from align.pair_reference import PairReferences, ReferenceOptions
    from align.roi import foreground_mask

    Kh, Kl, T_lq_hq = rig[:3]
    r = PairReferences(lambda i: dh, K_hq=Kh, K_lq=Kl, T_lq_hq=T_lq_hq, t_hq_us=np.array([0]), background=bg,
                       options=ReferenceOptions(reference_edges=name, motion=False))(0, 0.0)
    roi = foreground_mask(np.where(np.isfinite(r.depth), r.depth, lq), bg) & np.isfinite(dl)
    e = (r.depth - dl)[roi & np.isfinite(r.depth)]
    acc.setdefault(name, np.zeros(3))
    acc[name] += (int((np.abs(e) > 0.3).sum()), int((r.edge_mask & roi).sum()), int(roi.sum()))
    return r


def test_footprint_rule_hides_what_the_dropped_near_samples_covered():
    """``footprint-fg`` against ``strict-fg`` on an analytic scene (a slab 0.7 m in front of two boards, all in
    front of the room) whose near surfaces lose their last 3 HQ samples to mixing: the boards' samples the HQ
    camera saw beside the slab leak inside the LQ silhouette, in front of the background, and the strict band,
    which needs a nearer *reference* pixel, misses many; the mixes' footprints hide them. Its reference is the
    plain warp with the pixels more than OCCLUDER_REL behind the occluders (in front of the background) masked,
    then strict-fg's band; it leaves under half the whole-jump errors in the ROI at under 2 % more masked."""
    from scipy.ndimage import minimum_filter

    from align.reference_edges import FOOTPRINT_BAND_PX, OCCLUDER_REL, footprint_occluders
    from align.roi import in_front

    acc = {}
    for rng, dh, dl, bg, rig in _slab_scenes(0):
        Kh, Kl, T_lq_hq = rig[:3]
        dh = _near_side_mixes(dh, rng, width=3)
        dh = (dh * (1 + 0.001 * rng.standard_normal(dh.shape))).astype(np.float32)
        lq = minimum_filter(np.where(np.isfinite(dl), dl, 99), 5).astype(np.float32)
        for name in ("strict-fg", "footprint-fg"):
            r = _reference_and_counts(dh, name, rig=rig, dl=dl, bg=bg, lq=lq, acc=acc)
            if name == "footprint-fg":  # by formula: hidden behind the occluders, in front of the background
                warper = DepthWarper(Kh, Kl, T_lq_hq, edge_reach=0.0)
                plain, occ = warper(dh), footprint_occluders(warper, dh)
                hide = (plain - occ > OCCLUDER_REL * occ) & in_front(plain, bg)
                hide |= occluded_side(np.where(hide, np.nan, plain), radius_px=FOOTPRINT_BAND_PX) & in_front(plain, bg)
                assert np.array_equal(r.depth, np.where(hide, np.float32(np.nan), plain), equal_nan=True)
    strict, fp = acc["strict-fg"], acc["footprint-fg"]
    assert strict[0] >= 200, acc  # the leaks exist on this scene
    assert fp[0] <= 0.5 * strict[0], acc
    assert fp[1] - strict[1] < 0.02 * fp[2], acc


def _far_side_mixes_near(d, rng, *, offset_rel, fraction=0.5):
    """Far-side samples next to a nearer surface (a 3x3 neighbour > 0.1 m nearer) replaced, with probability
    ``fraction``, by a mix that reads ``offset_rel`` behind the near surface: within the warp's continuity test
    (it links them into the near surface, one HQ step past its silhouette) but off the surface's line by more than
    the noise. The truth there is the far surface."""
    from scipy.ndimage import minimum_filter

    f = np.where(np.isfinite(d), d, 99.0)
    near = minimum_filter(f, 3)
    band = np.isfinite(d) & (f - near > 0.1) & (rng.random(d.shape) < fraction)
    return np.where(band, near * (1 + offset_rel), d).astype(np.float32), band


def test_footprint_mixed_rule_drops_the_mixes_that_extend_a_near_surface_and_counts_what_it_drops():
    """``footprint-mixed-fg`` against ``footprint-fg`` on slabs in front of a room whose HQ silhouettes carry far-side
    mixes that read 0.8 % behind the near surface (linked by the warp's continuity test: 3 % jump, 1 % slope; off
    the line by > 3 noise deviations at 0.1 % noise). ``footprint-fg`` warps them as the near surface one HQ step
    too far: whole-jump errors inside the ROI. ``footprint-mixed-fg``'s reference is, by formula, the warp without
    :func:`align.mixed_pixels.mixed_samples` (the plain warp's value kept where it is not in front of the background),
    the pixels the plain warp had there and those more than OCCLUDER_REL behind the occluders masked, then the band;
    its mask holds every pixel it dropped; and it leaves at most a quarter of footprint-fg's whole-jump errors."""
    from align.mixed_pixels import mixed_samples
    from align.reference_edges import FOOTPRINT_BAND_PX, OCCLUDER_REL, footprint_occluders
    from align.roi import in_front

    acc = {}
    for rng, dh, dl, bg, rig in _slab_scenes(10):
        Kh, Kl, T_lq_hq = rig[:3]
        dh = (dh * (1 + 0.001 * rng.standard_normal(dh.shape))).astype(np.float32)
        dh, _ = _far_side_mixes_near(dh, rng, offset_rel=0.008)
        for name in ("footprint-fg", "footprint-mixed-fg"):
            r = _reference_and_counts(dh, name, rig=rig, dl=dl, bg=bg, lq=dl, acc=acc)
            if name == "footprint-mixed-fg":  # by formula
                warper = DepthWarper(Kh, Kl, T_lq_hq, edge_reach=0.0)
                plain, occ = warper(dh), footprint_occluders(warper, dh)
                out = warper(np.where(mixed_samples(dh, edge_rel=0.03, k_sigma=3.0), np.nan, dh).astype(np.float32))
                dropped = np.isfinite(plain) & ~np.isfinite(out)
                out = np.where(dropped & ~in_front(plain, bg), plain, out)
                dropped &= in_front(plain, bg)
                hide = ((out - occ > OCCLUDER_REL * occ) & in_front(out, bg)) | dropped
                hide |= occluded_side(np.where(hide, np.nan, out), radius_px=FOOTPRINT_BAND_PX) & in_front(out, bg)
                assert np.array_equal(r.depth, np.where(hide, np.float32(np.nan), out), equal_nan=True)
                assert not (dropped & ~r.edge_mask).any()   # every dropped pixel is counted as masked
    fp, fm = acc["footprint-fg"], acc["footprint-mixed-fg"]
    assert fp[0] >= 30, acc  # the near-looking mixes leave whole-jump errors in footprint-fg's reference
    assert fm[0] <= 0.25 * fp[0], acc
    assert fm[1] > fp[1], acc   # the dropped pixels are counted


def _colour_edge_loop(z, c, rel):
    """The colour-edge score pixel by pixel (the formula of :func:`align.reference_edges.colour_edge_score`)."""
    H, W = z.shape
    out = np.full((H, W), np.nan)
    for i in range(H):
        for j in range(W):
            if not np.isfinite(z[i, j]):
                continue
            a_in, a_out = np.sqrt(3.0) * 255.0, np.inf
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    ii, jj = i + di, j + dj
                    if (di or dj) and 0 <= ii < H and 0 <= jj < W:
                        d = float(np.linalg.norm(c[ii, jj].astype(float) - c[i, j].astype(float)))
                        if np.isfinite(z[ii, jj]) and abs(z[ii, jj] - z[i, j]) <= rel * z[i, j]:
                            a_in = min(a_in, d)
                        elif not np.isfinite(z[ii, jj]) or z[ii, jj] > (1 + rel) * z[i, j]:
                            a_out = min(a_out, d)
            if np.isfinite(a_out):
                out[i, j] = a_in - a_out
    return out


def test_colour_edge_score_equals_a_direct_loop():
    from align.reference_edges import colour_edge_score

    rng = np.random.default_rng(3)
    z = rng.choice(np.array([1.0, 1.05, 2.0, 3.0, np.nan], np.float32), size=(13, 17))
    c = rng.integers(0, 256, size=(13, 17, 3)).astype(np.uint8)
    np.testing.assert_allclose(colour_edge_score(z, c), _colour_edge_loop(z, c, 0.1), rtol=1e-5, atol=1e-3)


def _mosaic(shape, rng, cell, lo, hi):
    """A random colour mosaic of ``cell``-pixel squares, every channel in ``[lo, hi)``."""
    H, W = shape
    cells = rng.integers(lo, hi, size=(H // cell + 1, W // cell + 1, 3))
    return cells[np.arange(H)[:, None] // cell, np.arange(W)[None, :] // cell].astype(np.uint8)


def test_colour_edge_rule_masks_the_pixels_whose_colour_lies_past_the_reference_silhouette():
    """A disc (2 m) before a wall (5 m), each with its own random colour mosaic (the simulator's kind of texture, at
    2 px per cell); the LQ colour is point-sampled from the truth. The reference extends the disc by single pixels
    here and there along its silhouette (the error a concave corner or a slit one HQ step wide leaves): those
    pixels carry the wall's colour. (A continuous band of wrong pixels shares its colour along the band: the rule
    does not see it, and is not meant to.)
    The rule must mask most of them and almost none of the disc's true silhouette pixels; the rules without the
    colour edge, and a missing colour, mask nothing."""
    from align.reference_edges import colour_edge_mask

    rng = np.random.default_rng(5)
    H = W = 120
    yy, xx = np.mgrid[:H, :W]
    caught = wrong_total = false = true_edge = 0
    for cx, cy, r in ((40, 50, 22), (80, 70, 30), (60, 60, 15)):
        disc = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
        truth = np.where(disc, 2.0, 5.0).astype(np.float32)
        color = np.where(disc[..., None], _mosaic((H, W), rng, 2, 0, 256), _mosaic((H, W), rng, 2, 0, 256))
        ring = ((xx - cx) ** 2 + (yy - cy) ** 2 <= (r + 1.5) ** 2) & ~disc
        grown = ring & (np.arctan2(yy - cy, xx - cx) > -1.0) & ((xx + 2 * yy) % 9 == 0)  # single pixels, apart
        ref = np.where(disc | grown, 2.0, np.nan).astype(np.float32)  # the wall side: a hole of the reference
        m = colour_edge_mask(ref, color)
        silhouette = disc & ~(np.roll(disc, 1, 0) & np.roll(disc, -1, 0) & np.roll(disc, 1, 1) & np.roll(disc, -1, 1))
        caught += int((m & grown).sum()); wrong_total += int(grown.sum())
        false += int((m & disc).sum()); true_edge += int(silhouette.sum())
        assert not (m & ~np.isfinite(ref)).any()
        rule = EdgeRule.named("footprint-colour-fg")
        assert rule.colour_edge and (rule.colour_mask(ref, color) == m).all()
        assert not rule.colour_mask(ref, None).any() and not EdgeRule.named("footprint-fg").colour_mask(ref, color).any()
        assert rule.to_dict()["colour_edge"]["margin"] > 0
    assert caught >= 0.6 * wrong_total, (caught, wrong_total)
    assert false <= 0.1 * true_edge, (false, true_edge)


def test_doctests():
    import doctest

    import align.reference_edges

    assert doctest.testmod(align.reference_edges).failed == 0
