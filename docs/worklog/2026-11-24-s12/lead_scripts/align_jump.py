"""align_jump.py R_SMALL R_BIG REL_BIG depthbench-args...: footprint-fg whose far-side band is R_SMALL wide at every
edge (edge_rel 3 %) and R_BIG wide where the nearer surface is more than REL_BIG nearer (measurement only)."""
import sys
import numpy as np, cv2
import align.reference_edges as R
r_small, r_big, rel_big = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
R.RULES['footprint-fg'] = (0.0, r_big, False, True, True)
_orig = R.occluded_side
def two_band(depth, *, radius_px=2, edge_rel=0.03):
    return _orig(depth, radius_px=r_small, edge_rel=edge_rel) | _orig(depth, radius_px=r_big, edge_rel=rel_big)
R.occluded_side = two_band
from depthbench.cli import main
sys.exit(main(sys.argv[4:]))
