"""Exceptions of the bench package: one root, :class:`BenchError`, and one subclass per kind of problem.

Every message is one line that names the file, dataset, frame or value and the problem (never a
command-line flag: the CLI adds the flag); the command line turns any of them into exit status 2
without a traceback.
"""
from depthbench.errors import DepthbenchError


class BenchError(DepthbenchError):
    """Root of benchmark errors."""


class MetricInputError(BenchError):
    """Arrays given to a metric do not fit together (shapes, intrinsics, parameters)."""


class MethodOutputError(BenchError):
    """A method returned something that is not a depth image of the input's size."""


class MethodRunError(BenchError):
    """A method refused a frame (its own one-line error, with the dataset and frame added)."""


class ResultsFormatError(BenchError):
    """A results folder or table that this version cannot read."""


class SchemaVersionError(ResultsFormatError):
    """A results table or folder written with another schema version."""


class EmptyReferenceError(BenchError):
    """A dataset has no valid reference pixel (inside its ROI) in any frame: nothing to score against."""


class DatasetError(BenchError):
    """A path that is not (a folder of) aligned datasets, or two datasets with one name."""
