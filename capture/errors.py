"""Exceptions of the capture package."""
from depthbench.errors import DepthbenchError


class CaptureError(DepthbenchError):
    """Root of capture errors."""


class SessionFormatError(CaptureError):
    """A session folder (or a file in it) does not follow the documented format."""


class CalibrationError(CaptureError):
    """Intrinsics or extrinsics that cannot be right (non-positive focal length, non-rigid matrix...)."""


class DeviceError(CaptureError):
    """A sensor could not be opened or stopped delivering frames."""


class RigError(CaptureError):
    """A rig file (TOML) that cannot be used: syntax, unknown driver, missing serial, bad stream settings."""


class RecordingError(CaptureError):
    """Recording stopped on a condition the user must act on (disk full, a sensor stopped delivering)."""


class DiskSpaceError(RecordingError):
    """A recording would need more disk space than its output's file system has free."""

    cli_hint = "pass a smaller --seconds, or --no-space-check to record anyway"
