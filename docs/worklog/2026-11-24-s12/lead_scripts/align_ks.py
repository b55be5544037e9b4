"""align_ks.py K depthbench-args...: footprint-mixed-fg with the mixed-sample test at K noise deviations (default 3)
(measurement only)."""
import sys, dataclasses
import align.reference_edges as R
k = float(sys.argv[1])
_named = R.EdgeRule.named.__func__
def named(cls, name, *, edge_rel=0.03):
    return dataclasses.replace(_named(cls, name, edge_rel=edge_rel), k_sigma=k)
R.EdgeRule.named = classmethod(named)
from depthbench.cli import main
sys.exit(main(sys.argv[2:]))
