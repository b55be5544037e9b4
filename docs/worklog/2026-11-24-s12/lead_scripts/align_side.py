"""align_side.py MODE RADIUS depthbench-args...: footprint-fg whose far-side band is a half-disc: only offsets o to a
nearer pixel with o . d > 0 (MODE strict) or >= 0 (MODE incl), d = -(HQ centre's x, y in the LQ frame), fixed per
session (measurement only)."""
import sys
import numpy as np, cv2
import align.reference_edges as R
import align.pair_reference as P
mode, radius = sys.argv[1], int(sys.argv[2])
back = int(mode[4:]) if mode.startswith('back') else -1
R.RULES['footprint-fg'] = (0.0, radius, False, True, True)
DIR = [None]

def half_side(depth, *, radius_px=2, edge_rel=0.03):
    z = np.asarray(depth, np.float32)
    zi = np.where(np.isfinite(z), z, np.inf).astype(np.float32)
    H, W = z.shape
    d = DIR[0]
    nearest = np.full((H, W), np.inf, np.float32)
    for dy in range(-radius_px, radius_px + 1):
        for dx in range(-radius_px, radius_px + 1):
            if dx * dx + dy * dy > radius_px * radius_px + radius_px or (dx == 0 and dy == 0):
                continue
            dot = dx * d[0] + dy * d[1]
            if back >= 0:
                if dot <= 1e-9 and dx * dx + dy * dy > back * back + back:
                    continue
            elif dot < -1e-9 or (mode == 'strict' and dot <= 1e-9):
                continue
            sh = np.full((H, W), np.inf, np.float32)
            sh[max(0, -dy):H - max(0, dy), max(0, -dx):W - max(0, dx)] = zi[max(0, dy):H - max(0, -dy), max(0, dx):W - max(0, -dx)]
            nearest = np.minimum(nearest, sh)
    with np.errstate(invalid='ignore'):
        return np.isfinite(z) & (z - nearest > edge_rel * nearest)

R.occluded_side = half_side
orig_init = P.PairReferences.__init__ if hasattr(P, 'PairReferences') else None
_init = P.PairReferences.__init__
def init(self, read_hq, **kw):
    t = np.asarray(kw['T_lq_hq'].t, float)
    DIR[0] = -t[:2] / np.linalg.norm(t[:2])
    _init(self, read_hq, **kw)
P.PairReferences.__init__ = init
from depthbench.cli import main
sys.exit(main(sys.argv[3:]))
