"""occ_cost.py: CPU ms per demo frame of the plain warp, footprint_occluders, and forward_map alone (process_time)."""
import sys, csv, time
import numpy as np
sys.path.insert(0, '/work/wt/refedge3')
from align.dataset import AlignedDataset
from align.warp import DepthWarper
from align.reference_edges import footprint_occluders, EdgeRule
from capture.camera import Intrinsics, Transform
from capture.session import open_session
root, sroot = '/tmp/refedge3/al_base_demo', '/tmp/refedge3/demo'
ds = AlignedDataset(root); m = ds.meta
Kl, Kh = Intrinsics.from_dict(m['lq_intrinsics']), Intrinsics.from_dict(m['hq_intrinsics']); T = Transform.from_list(m['T_lq_hq'])
rows = list(csv.DictReader(open(f'{root}/frames.csv')))
s = open_session(sroot)
hqs = [s.read_depth('hq', int(r['hq_frame'])) for r in rows]
w = DepthWarper(Kh, Kl, T, edge_reach=0.0)
rule = EdgeRule.named('footprint-fg')
fns = {'warp': lambda d: w(d), 'forward_map': lambda d: w.forward_map(d), 'occluders': lambda d: footprint_occluders(w, d),
       'rule.warp': lambda d: rule.warp(w, d)}
for f in fns.values():
    f(hqs[0])
res = {k: [] for k in fns}
for rep in range(5):
    for k, f in fns.items():
        t = time.process_time()
        for d in hqs:
            f(d)
        res[k].append((time.process_time() - t) / len(hqs) * 1000)
print(" ".join(f"{k} {np.median(v):.2f} ms" for k, v in res.items()))
