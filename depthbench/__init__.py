"""depthbench: RGB-D capture, alignment and depth-denoising benchmark suite.

The suite is four packages with arrows pointing one way::

    capture  ->  align  ->  methods  ->  bench

``depthbench`` itself only holds the root exception and the console command that
dispatches to each package's own ``cli`` module.
"""
from depthbench.errors import DepthbenchError

__version__ = "0.1.0"
__all__ = ["DepthbenchError", "__version__"]
