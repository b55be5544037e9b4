"""Edge-mix statistic for a ToF depth image (NaN = invalid), no truth needed.

band: pixels whose 5x5 window of valid depths spans a jump > jump_m (near = min, far = max).
w = (far - z) / (far - near) (1 = near side value, 0 = far side value); mixed: lo < w < hi.
q: share of near-valued among the near/far-valued 8-neighbours (w_n > hi / w_n < lo w.r.t. the
centre's near/far): the pixel's position across the edge, read from its neighbours.
"""
import numpy as np, cv2

LO, HI = 0.15, 0.85

def edge_pixels(depth, fov, jump_m=0.1):
    v = np.isfinite(depth) & (depth > 0)
    k5 = np.ones((5, 5), np.uint8)
    near = cv2.erode(np.where(v, depth, 1e3).astype(np.float32), k5)
    far = cv2.dilate(np.where(v, depth, 0).astype(np.float32), k5)
    span = far - near
    core = jump_core(np.where(v, depth, np.nan).astype(np.float32), jump_m)
    band = fov & cv2.dilate(core.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool) & (span > jump_m)
    return v, near, far, band

def jump_core(z, jump_m, gmax=3):
    """Pixels of a discontinuity along x or y: z[i] and z[i+g] (g <= gmax, anything between) differ
    by > jump_m more than the slope outside them predicts (a grazing floor is not an edge)."""
    H, W = z.shape
    core = np.zeros((H, W), bool)
    for zz, tr in ((z, False), (z.T, True)):
        h, w = zz.shape
        c = np.zeros((h, w), bool)
        p = np.pad(zz, ((0, 0), (2, gmax + 2)), constant_values=np.nan)  # p[:, j + 2] = zz[:, j]
        for g in range(1, gmax + 1):
            a = p[:, 2:2 + w]; b = p[:, 2 + g:2 + g + w]
            sa = (a - p[:, 0:w]) / 2; sb = (p[:, 4 + g:4 + g + w] - b) / 2
            slope = np.where(np.isfinite(sa) & np.isfinite(sb), (sa + sb) / 2, np.where(np.isfinite(sa), sa, np.where(np.isfinite(sb), sb, 0.0)))
            inner = np.ones((h, w), bool)
            for k in range(1, g):  # the pixels between: invalid or between a and b
                m = p[:, 2 + k:2 + k + w]
                inner &= ~np.isfinite(m) | ((m - np.minimum(a, b)) * (np.maximum(a, b) - m) >= 0)
            hit = np.isfinite(a) & np.isfinite(b) & (np.abs(b - a - g * slope) > np.maximum(jump_m, 0.7 * np.abs(b - a))) & inner
            for k in range(0, g + 1):
                c[:, k:] |= hit[:, :w - k] if k else hit
        core |= c.T if tr else c
    return core


def per_pixel(depth, fov, jump_m=0.1, jump_hi=None, truth=None):
    v, near, far, band = edge_pixels(depth, fov, jump_m)
    if jump_hi is not None:
        band &= ~edge_pixels(depth, fov, jump_hi)[3]
    if truth is not None:  # simulated: only where the truth has a jump (not a grazing floor)
        t = np.where(np.isfinite(truth), truth, 20.0).astype(np.float32)
        k = np.ones((3, 3), np.uint8)
        tj = (cv2.dilate(t, k) - cv2.erode(t, k)) > jump_m
        band &= cv2.dilate(tj.astype(np.uint8), k).astype(bool)
    H, W = depth.shape
    z = np.where(v, depth, np.nan)
    w = (far - z) / np.maximum(far - near, 1e-6)
    nn = np.zeros((H, W), np.int32); nf = np.zeros((H, W), np.int32)
    zp = np.pad(z, 1, constant_values=np.nan)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy == 0 and dx == 0:
                continue
            zn = zp[1 + dy:1 + dy + H, 1 + dx:1 + dx + W]
            wn = (far - zn) / np.maximum(far - near, 1e-6)
            nn += (wn > HI); nf += (wn < LO)
    q = np.where(nn + nf > 0, nn / np.maximum(nn + nf, 1), np.nan)
    return dict(band=band, valid=v & band, w=w, q=q)

def summarise(recs, idx=None):
    """recs: list of dicts with arrays (flattened per cluster): band, valid, w, q."""
    band = sum(r["band"] for r in recs); valid = sum(r["valid"] for r in recs)
    mixed = sum(r["mixed"] for r in recs)
    out = dict(band=band, invalid=1 - valid / max(band, 1), mixed=mixed / max(valid, 1))
    wf = np.concatenate([r["w_far"] for r in recs] + [np.zeros(0)]); wn = np.concatenate([r["w_near"] for r in recs] + [np.zeros(0)])
    out["w_farq"] = wf.mean() if wf.size else np.nan      # mean w of mixes whose neighbours are mostly far
    out["w_nearq"] = wn.mean() if wn.size else np.nan
    out["diff"] = out["w_nearq"] - out["w_farq"]
    out["far_hi"] = (wf > 0.5).mean() if wf.size else np.nan  # far-side mixes reading nearer than the midpoint
    out["n_far"], out["n_near"] = wf.size, wn.size
    return out

def clusters(d, tile=32, keyed=False):
    """Per tile of the image: the counts and the mixed w's split by q."""
    recs = []
    H, W = d["band"].shape
    for y in range(0, H, tile):
        for x in range(0, W, tile):
            s = (slice(y, y + tile), slice(x, x + tile))
            b = d["band"][s]; vb = d["valid"][s]
            if b.sum() == 0:
                continue
            w = d["w"][s][vb]; q = d["q"][s][vb]
            m = (w > LO) & (w < HI) & np.isfinite(q)
            r = dict(band=int(b.sum()), valid=int(vb.sum()), mixed=int(((w > LO) & (w < HI)).sum()),
                     w_far=w[m & (q < 0.5)], w_near=w[m & (q > 0.5)])
            recs.append(((y, x), r) if keyed else r)
    return recs

def boot(recs, key, n=2000, seed=0):
    rng = np.random.default_rng(seed)
    vals = []
    for _ in range(n):
        i = rng.integers(0, len(recs), len(recs))
        vals.append(summarise([recs[j] for j in i])[key])
    return np.nanpercentile(vals, [2.5, 97.5])

def report(name, recs, keys=("invalid", "mixed", "w_nearq", "w_farq", "diff", "far_hi")):
    s = summarise(recs)
    parts = [f"{name}: clusters {len(recs)} band {s['band']} mixes near/far-q {s['n_near']}/{s['n_far']}"]
    for k in keys:
        lo, hi = boot(recs, k, n=500)
        parts.append(f"{k} {s[k]:.3f} [{lo:.3f}, {hi:.3f}]")
    print(" | ".join(parts), flush=True)
    return s
