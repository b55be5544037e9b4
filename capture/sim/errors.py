"""Exceptions of the simulator."""
from capture.errors import CaptureError


class SimulationError(CaptureError):
    """A simulator option or parameter that cannot be simulated (unknown rig, bad effect value...)."""
