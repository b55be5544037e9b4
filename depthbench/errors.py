"""The root of every exception the suite raises on purpose.

Each package derives its own type (``capture.CaptureError``, ``align.AlignError``,
``methods.MethodError``, ``bench.BenchError``). The command line turns any of them into a
one-line message and exit status 2, never a traceback.
"""


class DepthbenchError(Exception):
    """Bad input or an unrecoverable condition that the user can act on.

    The message must be one line that names the file or argument and the problem, in the
    library's terms (values, not command-line flags). ``cli_hint``: what the command line adds
    after it (e.g. the flag that overrides the check), unless the message says it already.
    """

    exit_code = 2
    cli_hint: str | None = None


class OutputExistsError(DepthbenchError):
    """An output path exists and ``force`` was not given."""

    cli_hint = "pass --force to replace it"


class UnsafePathError(DepthbenchError):
    """A path read from a file points outside the folder it must stay in."""


class FrameError(DepthbenchError):
    """A frame file or image that the frame codec (:mod:`depthbench.frames`) cannot write or read."""


class OutputInsideInputError(DepthbenchError):
    """An output path that is an input, lies inside one, or contains one."""
