"""align_band.py MASK_PX depthbench-args...: depthbench with footprint-fg's far-side band MASK_PX wide (default 3), to
see what budget a narrower band frees for other witnesses (measurement only)."""
import sys
import align.reference_edges as R
R.RULES['footprint-fg'] = (0.0, int(sys.argv[1]), False, True, True)
from depthbench.cli import main
sys.exit(main(sys.argv[2:]))
