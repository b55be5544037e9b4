"""A demo results folder without the learned methods (every non-learned registered method)."""
import sys
from depthbench.demo import DemoConfig, run_demo
run_demo(sys.argv[1], force=True, config=DemoConfig(learned=False, jobs=1, progress=False, time_shift_ms=25.0))
