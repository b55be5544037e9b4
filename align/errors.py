"""Exceptions of the align package (every class the package raises on purpose lives here).

Every error is one line that names the file, stream or value and the problem; the command line
turns it into exit status 2 without a traceback. Library messages name the value (an option of
:class:`align.pipeline.AlignOptions`, a range in ms), never a command-line flag: an error about
one option carries its name in ``option``, and the command line adds the flag.
"""
from depthbench.errors import DepthbenchError


class AlignError(DepthbenchError):
    """Root of alignment errors.

    Args:
        message: one line. option: the :class:`align.pipeline.AlignOptions` field the error is
            about (``None``: none); the command line prefixes the matching flag.
    """

    def __init__(self, message: str = "", *, option: str | None = None) -> None:
        super().__init__(message)
        self.option = option


class OptionError(AlignError, ValueError):
    """An option value outside its domain (``option`` names it)."""


class AlignedFormatError(AlignError):
    """An aligned dataset folder does not follow the documented format."""


class UnobservableError(AlignError):
    """The data cannot determine a quantity (e.g. the time shift of a static scene).

    ``estimate``: the :class:`align.time_shift.ShiftEstimate` as far as it got (``observable``
    False, ``reason`` set), for callers that go on with a declared shift.
    """

    def __init__(self, message: str = "", *, estimate=None, option: str | None = None) -> None:
        super().__init__(message, option=option)
        self.estimate = estimate


class AssociationError(AlignError):
    """Two timestamp streams give no pairs (non-overlapping time ranges, a shift far outside them...)."""


class FeatureError(AlignError):
    """Too few colour feature matches to fit anything (no colour stream, no texture, no overlap)."""


class ShiftRangeError(AlignError):
    """The best time shift lies on the edge of the search range: the answer may lie outside it.

    ``estimate``: the :class:`align.time_shift.ShiftEstimate` at the edge (``observable`` False).
    """

    def __init__(self, message: str = "", *, estimate=None, option: str | None = "shift_range_ms") -> None:
        super().__init__(message, option=option)
        self.estimate = estimate


class ShapeError(AlignError, ValueError):
    """Arrays whose shapes do not fit together (also a ``ValueError``: a bad argument)."""


class CalibrationBoardError(AlignError):
    """A ChArUco board could not be found or is seen too little to give a pose."""


class WarpInputError(ShapeError):
    """A depth image that does not fit the warp's source camera."""
