"""sim_inv.py FRACTION OUT depthbench-capture-simulate-args...: simulate with the HQ's flying_invalid_fraction set."""
import sys
from dataclasses import dataclass
import capture.sim.noise as N
frac = float(sys.argv[1])
@dataclass(frozen=True)
class T(N.TofNoise):
    flying_invalid_fraction: float = frac
N.TofNoise = T
from depthbench.cli import main
sys.exit(main(sys.argv[2:]))
