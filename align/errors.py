"""Exceptions of the align package.

Every error is one line that names the file, stream or argument and the problem; the command
line turns it into exit status 2 without a traceback.
"""
from depthbench.errors import DepthbenchError


class AlignError(DepthbenchError):
    """Root of alignment errors."""


class AlignedFormatError(AlignError):
    """An aligned dataset folder does not follow the documented format."""


class UnobservableError(AlignError):
    """The data cannot determine a quantity (e.g. the time shift of a static scene)."""


class AssociationError(AlignError):
    """Two timestamp streams give no pairs (non-overlapping time ranges, a shift far outside them...)."""


class FeatureError(AlignError):
    """Too few colour feature matches to fit anything (no colour stream, no texture, no overlap)."""


class ShiftRangeError(AlignError):
    """The best time shift lies on the edge of the search range: the answer may lie outside it."""


class CalibrationBoardError(AlignError):
    """A ChArUco board could not be found or is seen too little to give a pose."""
