"""The warped HQ reference's own error against truth on a simulated lq-hq session, and where it sits.

Run:  .venv/bin/python perf/reference_error.py SESSION [--frames 6]

SESSION is a simulated lq-hq session (``depthbench capture simulate``, e.g. the demo's). Each of
``--frames`` LQ frames spread over the session is paired with the HQ frame nearest to its instant
(truth's time shift), the HQ depth is warped with truth's ``T_lq_hq`` (so only the warp's own error
is left), and compared with the LQ truth depth on the region of interest computed as ``align`` does
(:func:`align.roi.foreground_mask` against :func:`align.roi.background_depth`). It prints:

* the time between the paired frames (ms) and the warp's MAE / RMSE (mm) and share of ROI pixels off
  by more than 50 mm (issue 12: on the demo, MAE 6.0 mm beside RMSE 64.9 mm);
* where the large errors are: which side (reference nearer or farther than truth), within 2 px of a
  hole of the reference, within 3 px of a depth edge of the truth, of the reference;
* the same for each edge rule of :mod:`align.reference_edges` (``midpoint``: the plain warp;
  ``strict``: the aligned dataset's default; ``mixed``: also the HQ's time-of-flight mixed samples),
  with the share of ROI pixels the rule masked (the plain warp has depth there, the reference none;
  ``strict-fg``/``mixed-fg`` mask only where the reference is in front of the background)
  and the share of ROI pixels without a reference at all (holes of the HQ sensor, shadows, masks);
* the ROI pixels without a reference, by cause: masked by the rule; the plain (midpoint) warp covers
  them (the gap past a surface's last sample the rule's warp leaves); the plain warp of the HQ truth
  depth covers them (HQ samples lost: mixed pixels dropped, dark or out of range); not even that
  (occlusion shadows, outside the HQ view);
* the mean over frames of each frame's MAE and RMSE (as the leaderboard's "HQ sensor" column), their
  ratio (issue 12 asks RMSE within 2x MAE), and the share of the squared error that pixels more than
  300 mm off (a surface the LQ camera does not see there) carry.
"""
from __future__ import annotations

import argparse

import cv2
import numpy as np

from align.reference_edges import RULES, EdgeRule
from align.roi import background_depth, foreground_mask
from align.warp import DepthWarper
from capture.session import open_session
from capture.truth import read_truth


def _disk(r: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))


def _edge(z: np.ndarray, rel: float = 0.03) -> np.ndarray:
    """Pixels with a 3x3 neighbour more than ``rel`` nearer or farther (NaN = none)."""
    f = np.where(np.isfinite(z), z, 0).astype(np.float32)
    near = cv2.erode(np.where(f > 0, f, 99).astype(np.float32), _disk(1))
    return (f > 0) & (cv2.dilate(f, _disk(1)) - near > rel * f)


def _within(mask: np.ndarray, r: float) -> np.ndarray:
    return cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, 5) <= r


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("session", help="a simulated lq-hq session (with truth/)")
    ap.add_argument("--frames", type=int, default=6, help="LQ frames spread over the session (default: %(default)s)")
    args = ap.parse_args()
    sess, tr = open_session(args.session), read_truth(args.session)
    t_hq, t_lq = sess.timestamps_us("hq"), sess.timestamps_us("lq")
    f_hq = sess.frames("hq", "depth")["frame_number"].to_numpy()
    f_lq = sess.frames("lq", "depth")["frame_number"].to_numpy()
    pairs = []
    for j in np.linspace(2, f_lq.size - 3, args.frames).round().astype(int):
        s = t_lq[j] - tr.time_shift_at_us(t_lq[j])
        i = int(np.argmin(np.abs(t_hq - s)))
        pairs.append((s - t_hq[i], sess.read_depth("hq", int(f_hq[i])), tr.depth("lq", int(f_lq[j])),
                      sess.read_depth("lq", int(f_lq[j])), tr.depth("hq", int(f_hq[i])).astype(np.float32)))
    print(f"{len(pairs)} pairs, HQ-LQ time apart (ms): {', '.join(f'{dt / 1000:+.2f}' for dt, *_ in pairs)}")
    plain = DepthWarper(sess.intrinsics("hq"), sess.intrinsics("lq"), tr.T_lq_hq, edge_reach=0.5)
    # what the plain warp covers, and what it would cover from the HQ truth (no mixes, no sensor holes)
    cover = [(np.isfinite(plain(hq)), np.isfinite(plain(hq_truth))) for _, hq, _, _, hq_truth in pairs]
    # one background model (from the plain warp) for every rule
    bg = background_depth(np.stack([np.where(np.isfinite(r), r, p[3]) for r, p in ((plain(p[1]), p) for p in pairs)]))
    for name in sorted(RULES, key=lambda n: n != "midpoint"):
        rule = EdgeRule.named(name)
        W = DepthWarper(sess.intrinsics("hq"), sess.intrinsics("lq"), tr.T_lq_hq, edge_reach=rule.edge_reach)
        _report(name, [(_reference(rule, W, hq, bg), truth, lq, c) for (_, hq, truth, lq, _), c in zip(pairs, cover)], bg)


def _reference(rule: EdgeRule, warper, hq, background=None):
    """The rule's reference and every pixel it masked (at the warp and after it), as ``align`` builds them
    (``background``: the ROI's, for the rules that mask only what it scores)."""
    ref, at_warp = rule.warp(warper, hq, background=background)
    ref, mask = rule.apply(ref, background=background)
    return ref, mask if at_warp is None else mask | at_warp


def _report(name: str, rows, bg) -> None:
    where = dict.fromkeys(("large", "ref farther", "ref nearer", "<= 2 px from a hole", "<= 3 px from a truth edge",
                           "<= 3 px from a reference edge"), 0)
    err, frame, n_roi, n_masked, n_none = [], [], 0, 0, 0
    why = dict.fromkeys(("masked by the rule", "past a surface's last sample", "HQ samples lost", "unseen by the HQ"), 0)
    for (ref, mask), truth, lq, (plain, plain_truth) in rows:
        roi = foreground_mask(np.where(np.isfinite(ref), ref, lq), bg) & np.isfinite(truth)
        use = roi & np.isfinite(ref)
        n_roi, n_masked, n_none = n_roi + roi.sum(), n_masked + (roi & mask).sum(), n_none + (roi & ~use).sum()
        none, m = roi & ~use, roi & ~use & mask
        for key, sel in zip(why, (m, none & ~m & plain, none & ~m & ~plain & plain_truth, none & ~m & ~plain & ~plain_truth)):
            why[key] += int(sel.sum())
        e = ref - truth
        err.append(e[use])
        f = np.abs(e[use]) * 1000
        frame.append((f.mean(), np.sqrt(np.mean(f ** 2))) if f.size else (np.nan, np.nan))
        big = use & (np.abs(e) > 0.05)
        for key, sel in (("large", big), ("ref farther", big & (e > 0)), ("ref nearer", big & (e < 0)),
                         ("<= 2 px from a hole", big & _within(~np.isfinite(ref), 2)),
                         ("<= 3 px from a truth edge", big & _within(_edge(truth), 3)),
                         ("<= 3 px from a reference edge", big & _within(_edge(ref), 3))):
            where[key] += int(sel.sum())
    e = np.abs(np.concatenate(err)) * 1000
    print(f"rule {name:8s}: MAE {e.mean():5.2f} mm  RMSE {np.sqrt(np.mean(e ** 2)):6.2f} mm  > 50 mm "
          f"{100 * np.mean(e > 50):.3f} %  masked by the rule {100 * n_masked / n_roi:.2f} %  "
          f"no reference {100 * n_none / n_roi:.2f} % of ROI pixels")
    fm = np.nanmean(np.array(frame), axis=0)
    print(f"  mean over frames (the leaderboard's 'HQ sensor'): MAE {fm[0]:.2f} mm  RMSE {fm[1]:.2f} mm  "
          f"RMSE / MAE {fm[1] / fm[0]:.2f}; share of the squared error from pixels > 300 mm off "
          f"{100 * np.sum(e[e > 300] ** 2) / max(np.sum(e ** 2), 1e-12):.1f} %")
    share = {k: f"{k} {v}" if k == "large" else f"{k} {100 * v / max(where['large'], 1):.0f} %" for k, v in where.items()}
    print("  errors > 50 mm: " + ", ".join(share.values()))
    print("  ROI pixels without reference: " + ", ".join(f"{k} {100 * v / n_roi:.2f} %" for k, v in why.items()))


if __name__ == "__main__":
    main()
