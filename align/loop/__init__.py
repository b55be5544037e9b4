"""Closing the loop on alignment (issue 12): residuals that name the effect the model lacks,
the extended model, and the error before and after.

* :mod:`align.loop.features` -- the feature residual as a function of every parameter;
* :mod:`align.loop.effects` -- the library of effect models (clock drift, rolling shutter,
  lens distortion of either colour camera, LQ depth scale and offset, duplicated/dropped frames);
* :mod:`align.loop.selection` -- held-out error over contiguous time blocks, the bootstrap
  threshold and the BIC guard;
* :mod:`align.loop.loop` -- the greedy search;
* :mod:`align.loop.stratify` -- residuals against each effect's signature, and what stays
  unexplained;
* :mod:`align.loop.run` -- the I/O glue for ``align_session`` (reads frames, warps the depth samples).
"""
from align.loop.loop import (DepthLoop, FeatureLoop, Finding, LoopOptions, fit_depth_effects,
                             fit_feature_effects)

__all__ = ["DepthLoop", "FeatureLoop", "Finding", "LoopOptions", "fit_depth_effects", "fit_feature_effects"]
