import sys, glob; sys.path.insert(0, "/work/notes/simtof")
import numpy as np, cv2
from edgestat import per_pixel, clusters, report
from capture.sim.noise import TofNoise, tof_depth
S = sys.argv[1] if len(sys.argv) > 1 else "/tmp/refedge3/demo"
def load(p, unit):
    d = cv2.imread(p, cv2.IMREAD_UNCHANGED).astype(np.float32) * unit; d[d == 0] = np.nan; return d
truth = [load(p, 1e-4) for p in sorted(glob.glob(f"{S}/truth/hq/depth/*.png"))]
rec = [load(p, 1e-3) for p in sorted(glob.glob(f"{S}/hq/depth/*.png"))]
def run(name, frames, lo, hi, tr):
    per_tile = {}
    side = []  # truth side statistic: (own truth near?, w) of mixed band pixels
    for d, t in zip(frames, truth):
        pp = per_pixel(d, np.ones(d.shape, bool), lo, hi, truth=t if tr else None)
        for key, r in clusters(pp, 32, keyed=True):
            T = per_tile.setdefault(key, dict(band=0, valid=0, mixed=0, w_far=[], w_near=[]))
            for f in ("band", "valid", "mixed"):
                T[f] += r[f]
            T["w_far"].append(r["w_far"]); T["w_near"].append(r["w_near"])
        k = np.ones((3, 3), np.uint8); tt = np.where(np.isfinite(t), t, 20.0).astype(np.float32)
        tn, tf = cv2.erode(tt, k), cv2.dilate(tt, k)
        m = pp["valid"] & (pp["w"] > 0.15) & (pp["w"] < 0.85)
        side.append(np.stack([((tt - tn) <= (tf - tt))[m], pp["w"][m]], 1))
    recs = [dict(T, w_far=np.concatenate(T["w_far"]), w_near=np.concatenate(T["w_near"])) for T in per_tile.values()]
    report(name, recs)
    s = np.concatenate(side)
    nr, fr = s[s[:, 0] == 1, 1], s[s[:, 0] == 0, 1]
    print(f"   truth side: mixes on near px {nr.size} mean w {nr.mean():.3f}; on far px {fr.size} mean w {fr.mean():.3f}, "
          f"far px reading nearer than midpoint {np.mean(fr > 0.5):.3f}", flush=True)
for lo, hi in ((0.1, 0.2), (0.2, None)):
    run(f"recorded HQ (uniform) {lo}-{hi}", rec, lo, hi, True)
    for mix in ("uniform", "coverage", "coverage-amplitude"):
        rng = np.random.default_rng(0)
        fr = [tof_depth(t, np.full(t.shape, 0.6, np.float32), noise=TofNoise(flying_mix=mix), rng=rng).depth for t in truth]
        run(f"offline {mix} {lo}-{hi}", fr, lo, hi, True)
