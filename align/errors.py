"""Exceptions of the align package."""
from depthbench.errors import DepthbenchError


class AlignError(DepthbenchError):
    """Root of alignment errors."""


class AlignedFormatError(AlignError):
    """An aligned dataset folder does not follow the documented format."""


class UnobservableError(AlignError):
    """The data cannot determine a quantity (e.g. the time shift of a static scene)."""
