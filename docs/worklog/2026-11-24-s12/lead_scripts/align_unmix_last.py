"""align_unmix.py K depthbench-args...: footprint-fg whose HQ edge mixes that the warp would keep (within edge_rel of
their surface's last sample, off the surface's line by > K noise deviations) are snapped onto that line before the
warp (the occluders still from the samples as measured). Measurement only."""
import sys
import numpy as np
import align.reference_edges as R
import align.mixed_pixels as M
k = float(sys.argv[1])
MODE = "last"

def unmix(depth, *, edge_rel=0.03, k_sigma=3.0):
    w = M._inverse(depth)
    s = M.relative_noise(depth, edge_rel=edge_rel)
    H, W = w.shape
    p = 3
    wp = np.full((H + 2 * p, W + 2 * p), np.nan, np.float32)
    wp[p:-p, p:-p] = w
    at = lambda dy, dx: wp[p + dy:p + dy + H, p + dx:p + dx + W]
    best = np.full((H, W), np.inf, np.float32)
    out = w.copy()
    with np.errstate(invalid="ignore"):
        for sy, sx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
            w1, w2, w3, wo = at(-sy, -sx), at(-2 * sy, -2 * sx), at(-3 * sy, -3 * sx), at(sy, sx)
            line3 = M._same(w2, w3, edge_rel)
            pred = np.where(line3, (4 * w1 + w2 - 2 * w3) / 3, 2 * w1 - w2)
            sd = np.where(line3, np.float32(np.sqrt(1 + 7 / 3) * s), np.float32(np.sqrt(6.0) * s))
            edge = M._same(w, w1, edge_rel) & M._same(w1, w2, edge_rel) & ~M._same(w, wo, edge_rel)
            dev = np.abs(w - pred) / (sd * w)
            take = edge & (dev > k_sigma) & (dev < best)
            out = np.where(take, w1 if MODE == "last" else pred, out)
            best = np.where(take, dev, best)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.isfinite(out) & (out > 0), 1 / out, np.nan).astype(np.float32)

_fw = R.EdgeRule._footprint_warp
def fw(self, warper, hq, *, motion, background):
    hq = np.asarray(hq, np.float32)
    u = unmix(hq, edge_rel=self.edge_rel, k_sigma=k)
    ref, fmap = warper.warp_with_map(u, motion=motion)
    occ = R.footprint_occluders(warper, hq, motion=motion)
    with np.errstate(invalid="ignore"):
        hide = ref - occ > R.OCCLUDER_REL * occ
    if self.scored_only and background is not None:
        hide &= R.in_front(ref, background)
    return np.where(hide, np.float32(np.nan), ref).astype(np.float32, copy=False), hide
R.EdgeRule._footprint_warp = fw
from depthbench.cli import main
sys.exit(main(sys.argv[2:]))
