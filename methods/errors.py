"""Exceptions of the methods package."""
from depthbench.errors import DepthbenchError


class MethodError(DepthbenchError):
    """Root of method errors (bad parameters, bad input arrays, unknown method)."""


class UnknownMethodError(MethodError):
    """A method name that is not registered."""
