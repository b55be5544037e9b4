"""The root of every exception the suite raises on purpose.

Each package derives its own type (``capture.CaptureError``, ``align.AlignError``,
``methods.MethodError``, ``bench.BenchError``). The command line turns any of them into a
one-line message and exit status 2, never a traceback.
"""


class DepthbenchError(Exception):
    """Bad input or an unrecoverable condition that the user can act on.

    The message must be one line that names the file or argument and the problem.
    """

    exit_code = 2


class OutputExistsError(DepthbenchError):
    """An output path exists and ``--force`` was not given."""


class UnsafePathError(DepthbenchError):
    """A path read from a file points outside the folder it must stay in."""
