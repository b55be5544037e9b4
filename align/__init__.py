"""Align: time association and shift search, extrinsic fit, depth warping, residual models,
and the aligned-dataset format. Imports ``capture``.

The algorithms live in pure numpy modules without I/O (``association``, ``time_shift``,
``features``, ``extrinsics``, ``warp``, ``roi``, ``residuals``, ``charuco``); reading sessions,
writing datasets and reports is in ``pipeline``/``report``/``cli``. The one library entry point is
:func:`align.pipeline.align_session`.
"""
from align.dataset import AlignedDataset, AlignedDatasetWriter, AlignedFrame
from align.errors import (AlignedFormatError, AlignError, AssociationError, CalibrationBoardError, FeatureError,
                          ShiftRangeError, UnobservableError)

__all__ = ["AlignError", "AlignedDataset", "AlignedDatasetWriter", "AlignedFormatError", "AlignedFrame",
           "AssociationError", "CalibrationBoardError", "FeatureError", "ShiftRangeError", "UnobservableError",
           "align_session"]


def __getattr__(name):  # lazy: importing align must not import OpenCV/matplotlib-heavy layers
    if name == "align_session":
        from align.pipeline import align_session

        return align_session
    raise AttributeError(name)
