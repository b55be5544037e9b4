"""Exceptions of the bench package."""
from depthbench.errors import DepthbenchError


class BenchError(DepthbenchError):
    """Root of benchmark errors."""
