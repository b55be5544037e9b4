"""Align: time association and shift search, extrinsic fitting, depth warping, residual models,
and the aligned-dataset format. Imports ``capture``."""
from align.dataset import AlignedDataset, AlignedDatasetWriter, AlignedFrame
from align.errors import AlignedFormatError, AlignError, UnobservableError

__all__ = ["AlignError", "AlignedDataset", "AlignedDatasetWriter", "AlignedFormatError", "AlignedFrame",
           "UnobservableError"]
