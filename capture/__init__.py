"""Capture: sensor drivers, the recorder, the simulator and the session format.

Imports nothing else of the project but ``depthbench`` (errors, file helpers).
"""
from capture.camera import Intrinsics, Transform
from capture.errors import CalibrationError, CaptureError, DeviceError, SessionFormatError
from capture.session import Session, SessionWriter, open_session

__all__ = ["CalibrationError", "CaptureError", "DeviceError", "Intrinsics", "Session", "SessionFormatError",
           "SessionWriter", "Transform", "open_session"]
