"""MAE of the flow reference against truth, per pair, as perf/reference_motion.py's flow column scores it.

DUMP=out.json [FLOW='{"fill_px": 8}'] python acc.py SESSION [SESSION ...]   (run from a checkout, PYTHONPATH=it)
Writes per session and pair: flow |error| sum (mm) and count on the ROI, plain likewise, ROI pixels with a plain
reference and net lost by flow. 10 pairs per session (--frames 10), strict edges.
"""
import os
os.environ.setdefault("OMP_NUM_THREADS", "1"); os.environ.setdefault("NUMBA_NUM_THREADS", "1")
import sys, json
import numpy as np, cv2
sys.path.insert(0, os.getcwd())
import perf.reference_motion as rm
from align.motion import MotionReference
from align.reference_edges import EdgeRule
from align.roi import background_depth, foreground_mask

rm.FLOW_OPTIONS.update(json.loads(os.environ.get("FLOW", "{}")))
cv2.setNumThreads(1)
out = {}
for root in sys.argv[1:]:
    rule = EdgeRule.named("strict")
    setup, warper, tr, pairs = rm._pairs(root, 10, rule)
    sess = setup.session
    warped = lambda i: warper(sess.read_depth("hq", int(setup.f_hq[i])))
    plain = MotionReference(warped, setup.t_hq, enabled=False)
    flow = MotionReference(warped, setup.t_hq, moved=rm._flow_motion(setup, warper, lambda i: sess.read_depth("hq", int(setup.f_hq[i]))))
    rows, refined, gains = [], [], []
    for i, j, dt in pairs:
        lq = sess.read_depth("lq", int(setup.f_lq[j]))
        rows.append((rule.apply(plain(i, dt)[0])[0], rule.apply(flow(i, dt)[0])[0], tr.depth("lq", int(setup.f_lq[j])), lq))
        refined.append(bool(flow._moved.scene_flow.last_refined)); gains.append(flow._moved.scene_flow.last_gain)
    bg = background_depth(np.stack([np.where(np.isfinite(r[0]), r[0], r[3]) for r in rows]))
    recs = []
    R = int(os.environ.get("RING", "1"))
    def ring(f):
        z = np.where(np.isfinite(f), f, np.float32(1e3)).astype(np.float32)
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * R + 1, 2 * R + 1))
        far = cv2.dilate(z, k)
        return np.isfinite(f) & (far > 1.03 * z)
    for (p, f, truth, lq), (i, j, dt), rf, gn in zip(rows, pairs, refined, gains):
        roi = foreground_mask(np.where(np.isfinite(p), p, lq), bg) & np.isfinite(truth)
        if abs(dt) > 1000 and R > 0:
            f = np.where(ring(f), np.float32(np.nan), f)
        ef = np.abs(f - truth)[roi & np.isfinite(f)] * 1000
        ep = np.abs(p - truth)[roi & np.isfinite(p)] * 1000
        recs.append(dict(hq=i, lq=j, dt_ms=dt / 1000, flow_sum=float(ef.sum()), flow_n=int(ef.size),
                         plain_sum=float(ep.sum()), plain_n=int(ep.size), refined=rf, gain=gn,
                         lost=int((roi & np.isfinite(p)).sum() - (roi & np.isfinite(f)).sum())))
    out[root] = recs
    fs, fn = sum(r["flow_sum"] for r in recs), sum(r["flow_n"] for r in recs)
    lost = 100 * sum(r["lost"] for r in recs) / max(sum(r["plain_n"] for r in recs), 1)
    print(f"{root}: flow MAE {fs / fn:.3f} mm, plain {sum(r['plain_sum'] for r in recs) / sum(r['plain_n'] for r in recs):.2f}, "
          f"net lost {lost:.2f} %, refined {sum(refined)}", flush=True)
if os.environ.get("DUMP"):
    json.dump(out, open(os.environ["DUMP"], "w"))
