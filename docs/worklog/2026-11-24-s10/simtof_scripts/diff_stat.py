"""Real minus simulated edge statistic (independent cluster bootstraps, 1000 each): far_hi and diff at
0.1-0.2 m jumps; mixed and invalid at > 0.2 m jumps."""
import sys, glob; sys.path.insert(0, "/work/notes/simtof")
import numpy as np, cv2
from edgestat import per_pixel, clusters, summarise
from capture.sim.noise import TofNoise, tof_depth
r = np.load("/work/notes/simtof/real.npz")
d = r["depth"].astype(np.float32) / 1000; d[d == 0] = np.nan; fov = r["ir"] > 0
S = "/tmp/refedge3/demo"
def load(p, unit):
    x = cv2.imread(p, cv2.IMREAD_UNCHANGED).astype(np.float32) * unit; x[x == 0] = np.nan; return x
truth = [load(p, 1e-4) for p in sorted(glob.glob(f"{S}/truth/hq/depth/*.png"))]
def sim_recs(frames, lo, hi):
    per_tile = {}
    for x, t in zip(frames, truth):
        for key, rr in clusters(per_pixel(x, np.ones(x.shape, bool), lo, hi, truth=t), 32, keyed=True):
            T = per_tile.setdefault(key, dict(band=0, valid=0, mixed=0, w_far=[], w_near=[]))
            for f in ("band", "valid", "mixed"):
                T[f] += rr[f]
            T["w_far"].append(rr["w_far"]); T["w_near"].append(rr["w_near"])
    return [dict(T, w_far=np.concatenate(T["w_far"]), w_near=np.concatenate(T["w_near"])) for T in per_tile.values()]
def bs(recs, key, n=1000, seed=1):
    rng = np.random.default_rng(seed)
    return np.array([summarise([recs[j] for j in rng.integers(0, len(recs), len(recs))])[key] for _ in range(n)])
for lo, hi, keys in ((0.1, 0.2, ("far_hi", "diff")), (0.2, None, ("mixed", "invalid"))):
    real = clusters(per_pixel(d, fov, lo, hi), 32)
    rb = {k: bs(real, k) for k in keys}
    for mix in ("uniform", "coverage", "coverage-amplitude"):
        rng = np.random.default_rng(0)
        fr = [tof_depth(t, np.full(t.shape, 0.6, np.float32), noise=TofNoise(flying_mix=mix), rng=rng).depth for t in truth]
        sr = sim_recs(fr, lo, hi)
        for k in keys:
            sb = bs(sr, k, seed=2)
            dd = rb[k] - sb
            print(f"jump {lo}-{hi} {k}: real {summarise(real)[k]:.3f} sim {mix} {summarise(sr)[k]:.3f}: "
                  f"real - sim {summarise(real)[k] - summarise(sr)[k]:+.3f} [{np.nanpercentile(dd, 2.5):+.3f}, {np.nanpercentile(dd, 97.5):+.3f}]", flush=True)
