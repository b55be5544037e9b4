"""One pair of acc.py's, traced: where the flow reference's error against truth lies (session 12, recheck).

PYTHONPATH=<checkout> python pair_diag.py SESSION PAIR_INDEX [OUT.png]
Prints, on the ROI as acc.py scores it: MAE, the share and the sum of |error| of pixels off by > 50 / > 300 mm, what
share of the error sum those carry, the sign (reference nearer/farther than truth), and the flow reference's
and the plain warp's error there. OUT.png: |error| of the flow reference (white = 300 mm+).
"""
import os
os.environ.setdefault("OMP_NUM_THREADS", "1"); os.environ.setdefault("NUMBA_NUM_THREADS", "1")
import sys
import numpy as np, cv2
sys.path.insert(0, os.getcwd())
import perf.reference_motion as rm
from align.motion import MotionReference
from align.reference_edges import EdgeRule
from align.roi import background_depth, foreground_mask

cv2.setNumThreads(1)
root, k = sys.argv[1], int(sys.argv[2])
rule = EdgeRule.named(os.environ.get("RULE", "strict"))
setup, warper, tr, pairs = rm._pairs(root, 10, rule)
sess = setup.session
warped = lambda i: rule.warp(warper, sess.read_depth("hq", int(setup.f_hq[i])))[0]
plain = MotionReference(warped, setup.t_hq, enabled=False)
flow = MotionReference(warped, setup.t_hq, moved=rm._flow_motion(setup, warper, lambda i: sess.read_depth("hq", int(setup.f_hq[i]))))
rows = []
for i, j, dt in pairs:
    lq = sess.read_depth("lq", int(setup.f_lq[j]))
    rows.append((rule.apply(plain(i, dt)[0])[0], rule.apply(flow(i, dt)[0])[0], tr.depth("lq", int(setup.f_lq[j])), lq))
bg = background_depth(np.stack([np.where(np.isfinite(r[0]), r[0], r[3]) for r in rows]))
p, f, truth, lq = rows[k]
roi = foreground_mask(np.where(np.isfinite(p), p, lq), bg) & np.isfinite(truth)
m = roi & np.isfinite(f)
e = (f - truth) * 1000
ae = np.abs(e)[m]
print(f"pair {k}: hq {pairs[k][0]} lq {pairs[k][1]} dt {pairs[k][2] / 1000:.2f} ms, ROI px {m.sum()}, flow MAE {ae.mean():.2f} mm, "
      f"plain MAE {np.abs((p - truth) * 1000)[roi & np.isfinite(p)].mean():.2f} mm")
for thr in (50, 300):
    big = m & (np.abs(e) > thr)
    print(f"  > {thr} mm: {big.sum()} px ({100 * big.sum() / m.sum():.2f} %), carrying {100 * np.abs(e)[big].sum() / ae.sum():.1f} % "
          f"of the error sum; reference nearer than truth on {100 * np.mean(e[big] < 0):.0f} %; MAE without them "
          f"{np.abs(e)[m & ~big].mean():.2f} mm")
    if big.any():
        ys, xs = np.nonzero(big)
        print(f"    bbox rows {ys.min()}-{ys.max()}, cols {xs.min()}-{xs.max()}; plain warp's |error| there median "
              f"{np.nanmedian(np.abs((p - truth) * 1000)[big]):.0f} mm, flow's {np.median(np.abs(e)[big]):.0f} mm")
if len(sys.argv) > 3:
    img = np.zeros(f.shape, np.uint8)
    img[m] = np.clip(np.abs(e)[m] / 300 * 255, 0, 255).astype(np.uint8)
    img[~roi] = 40
    cv2.imwrite(sys.argv[3], img)
