"""acc.py's score (10 pairs per session, ROI MAE of the flow-carried reference against truth) with the references
built as ``align`` builds them (:func:`align.pipeline.pair_references`, motion model "flow") under any edge rule,
e.g. the default ``footprint-fg`` (session 12, recheck). The ROI and its background are acc.py's (from the strict
plain warps), so rules are compared on the same pixels; the rule's masked share of those ROI pixels is printed.
ROI=rule: the ROI from the rule's own reference instead (``foreground_mask`` of the reference, else the LQ depth), as
the aligned dataset's scoring of a ``-fg`` rule sees it (those rules keep far-side pixels that the ROI does not score).

RULE=footprint-fg DUMP=out.json PYTHONPATH=<checkout> python acc_rule.py SESSION [SESSION ...]
"""
import os
os.environ.setdefault("OMP_NUM_THREADS", "1"); os.environ.setdefault("NUMBA_NUM_THREADS", "1")
import sys, json
import numpy as np, cv2
sys.path.insert(0, os.getcwd())
import perf.reference_motion as rm
from align.motion import MotionReference
from align.pair_reference import ReferenceOptions
from align.pipeline import pair_references
from align.reference_edges import EdgeRule
from align.roi import background_depth, foreground_mask

cv2.setNumThreads(1)
rule_name = os.environ.get("RULE", "footprint-fg")
out = {}
for root in sys.argv[1:]:
    strict = EdgeRule.named("strict")
    setup, warper, tr, pairs = rm._pairs(root, 10, strict)
    sess = setup.session
    plain = MotionReference(lambda i: warper(sess.read_depth("hq", int(setup.f_hq[i]))), setup.t_hq, enabled=False)
    lqs = [sess.read_depth("lq", int(setup.f_lq[j])) for _, j, _ in pairs]
    plains = [strict.apply(plain(i, dt)[0])[0] for i, _, dt in pairs]
    bg = background_depth(np.stack([np.where(np.isfinite(p), p, lq) for p, lq in zip(plains, lqs)]))
    refs = pair_references(setup, T_lq_hq=tr.T_lq_hq, background=bg,
                           options=ReferenceOptions(reference_edges=rule_name, motion_model="flow"))
    recs = []
    for (i, j, dt), p, lq in zip(pairs, plains, lqs):
        r = refs(i, dt)
        truth = tr.depth("lq", int(setup.f_lq[j]))
        src = r.depth if os.environ.get("ROI") == "rule" else p
        roi = foreground_mask(np.where(np.isfinite(src), src, lq), bg) & np.isfinite(truth)
        e = np.abs(r.depth - truth)[roi & np.isfinite(r.depth)] * 1000
        recs.append(dict(hq=i, lq=j, dt_ms=dt / 1000, flow_sum=float(e.sum()), flow_n=int(e.size),
                         roi_n=int(roi.sum()), masked=int((r.edge_mask & roi).sum()), model=r.motion.model,
                         lost=int((roi & np.isfinite(p)).sum() - e.size), plain_n=int((roi & np.isfinite(p)).sum()),
                         plain_sum=float((np.abs(p - truth)[roi & np.isfinite(p)] * 1000).sum())))
    out[root] = recs
    fs, fn = sum(r["flow_sum"] for r in recs), sum(r["flow_n"] for r in recs)
    print(f"{root}: {rule_name} flow MAE {fs / fn:.3f} mm, rule-masked {100 * sum(r['masked'] for r in recs) / sum(r['roi_n'] for r in recs):.2f} % "
          f"of ROI, net lost vs strict plain {100 * sum(r['lost'] for r in recs) / sum(r['plain_n'] for r in recs):.2f} %, "
          f"models {sorted(set(r['model'] for r in recs))}", flush=True)
if os.environ.get("DUMP"):
    json.dump(out, open(os.environ["DUMP"], "w"))
