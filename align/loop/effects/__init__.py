"""The library of effect models the loop can add to the base alignment model.

Each effect is a small class (one module each) with named parameters, their units and
finite-difference steps, and hooks into the feature model (:class:`align.loop.features.FeatureModel`):

* ``time_offset_us(data, v)``: added to each feature's instant (drift, HQ rolling shutter);
* ``sample_offset_us(data, stamps, v)``: added to each LQ track sample's stamp (LQ rolling shutter);
* ``lq_camera(K, v)``: the LQ colour camera the points are projected with (LQ lens);
* ``correct_points(data, X, v)``: the HQ points (HQ lens).

Effects of the depth (:mod:`align.loop.effects.depth`: ``z_LQ = s z_HQ + o``) and of the
frame sequence (:mod:`align.loop.effects.frames`: duplicated and dropped frames) act on other
data and are fitted by their own modules.

``FEATURE_EFFECTS`` lists the feature effects in the order of the greedy search's stages:
an effect with ``requires`` becomes a candidate only once that effect is in the model (the
lens's ``k2`` after ``k1``, its tangential terms after ``k2``).
"""
from align.loop.effects.base import Effect
from align.loop.effects.drift import ClockDrift
from align.loop.effects.lens import LensDistortion
from align.loop.effects.rolling_shutter import RollingShutter


def feature_effects() -> list[Effect]:
    """A fresh instance of every feature effect of the library."""
    return [ClockDrift(), RollingShutter("lq"), RollingShutter("hq"),
            LensDistortion("lq", ("k1",)), LensDistortion("lq", ("k2",), requires="lens_lq_k1"),
            LensDistortion("lq", ("p1", "p2"), requires="lens_lq_k2"),
            LensDistortion("hq", ("k1",)), LensDistortion("hq", ("k2",), requires="lens_hq_k1")]


__all__ = ["ClockDrift", "Effect", "LensDistortion", "RollingShutter", "feature_effects"]
