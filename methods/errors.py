"""Exceptions of the methods package."""
from depthbench.errors import DepthbenchError


class MethodError(DepthbenchError):
    """Root of method errors (bad parameters, bad input arrays, unknown method)."""


class UnknownMethodError(MethodError):
    """A method name that is not registered."""


class FrameRejectedError(MethodError):
    """A method refused a frame (its own error, with the dataset, frame and method key added).

    Wherever a method runs over a dataset (``methods run``, ``bench run``, the demo) the run stops
    on it with this one-line error and publishes nothing; see :mod:`methods.run`.
    """


class TrainingError(MethodError):
    """Root of the training errors: bad configs, manifests, checkpoints, runs."""


class ConfigError(TrainingError):
    """A training config file that cannot be used (unknown key, wrong type, not TOML)."""


class CheckpointError(TrainingError):
    """A weights/checkpoint file that is missing, corrupt, foreign or not tensors-only."""


class TrainingManifestError(TrainingError):
    """A training dataset manifest that is invalid or names a missing or changed dataset."""
