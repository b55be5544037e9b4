"""Depth noise from the sensors' physics (pure numpy + OpenCV filters, no I/O).

Stereo LQ (RealSense D415-like), in disparity space:

* disparity ``d = f * B / z`` (px; ``f`` focal length in px, ``B`` baseline in m);
* matching noise: ``d + subpixel_px * n`` with ``n`` a unit-variance Gaussian field, spatially
  correlated by a Gaussian of ``correlation_px`` (the matcher's window);
* quantisation of the disparity to ``disparity_step_px`` (1/32 px, the D415's sub-pixel step);
* so ``sigma_z ~= z**2 / (f * B) * sqrt(subpixel_px**2 + disparity_step_px**2 / 12)``: the
  quadratic growth with depth (the quantisation adds 0.6 % at 0.08 px and 1/32 px);
* no measurement where the right camera cannot see the point (occlusion shadows, and the band
  on the left that is outside the right camera's view), near depth edges (disparity range in a
  3x3 window over ``edge_threshold_px``, with probability ``edge_invalid_prob``), on dark
  (luminance < ``min_luminance``) or low-texture (local standard deviation of luminance in a
  ``texture_window_px`` window < ``min_contrast``) surfaces, outside ``[min_depth_m,
  max_depth_m]``, and a random ``random_invalid_fraction`` of pixels.

Effects found by ``depthbench bench diagnose`` on real captures (issue 13; all off by default, so
the default sensors behave as before; the measured values are in ``sensor_profiles.json``):

* ``noise_floor_m``: a depth-independent error added to the depth (same correlation as the
  matching noise), so ``sigma_z = sqrt(noise_floor_m**2 + (z**2 subpixel / (f B))**2)``: the
  D435 board's error at 0.67 m is 4 mm where ``z**2`` scaling from 1.5 m predicts 1.4 mm;
* ``outlier_fraction``: that fraction of measured pixels reads a depth drawn uniformly in
  ``[min_depth_m, max_depth_m]`` (the D435's pixels at up to 46 m);
* ``depth_offset_m`` / ``disparity_offset_px``: a calibration error: the depth off by a constant,
  or the disparity (``z = f B / (d + disparity_offset_px)``), which makes the error grow with depth.

Time-of-flight HQ (Kinect v2 / Azure-like), in depth:

* ``sigma(z) = sigma0_m + sigma_slope * max(z - z0_m, 0)`` (0.5 mm + 1 mm per metre beyond
  0.5 m, i.e. 0.1 % of the distance beyond 0.5 m), white;
* flying (mixed) pixels: where the true depth jumps by more than ``flying_jump_m`` inside a
  3x3 window, a ``flying_fraction`` of the pixels take a random mix ``w z_near + (1-w) z_far``,
  with the weight ``w`` drawn by ``flying_mix``:

  - ``"uniform"``: ``w ~ U[0, 1]`` whichever surface the pixel's centre sees (a pixel of the
    background can read next to the foreground);
  - ``"coverage"``: ``w`` is the share of the pixel's footprint the near surface covers. The
    renderer samples the pixel centre, so a pixel whose own true depth is the near surface is at
    least half covered by it: ``w ~ U[0.5, 1]``; one that sees the far surface, ``w ~ U[0, 0.5]``.
    (A straight silhouette at a uniform sub-pixel offset gives exactly this: a pixel whose centre
    lies ``d`` px from it, ``d ~ U[0, 1]`` for the pixels of a 3x3 jump, is mixed when ``d < 0.5``
    (probability 0.5, ``flying_fraction``) with coverage ``0.5 + d`` of its own side.) The mixed
    values then fall on the pixel's own side of the edge's midpoint. On the Azure Kinect capture
    (``docs/worklog/2026-11-24-s10/simtof.md``), at 0.1-0.2 m jumps 3 % [0, 8 %] of the mixes whose
    neighbours are mostly far read nearer than the midpoint; the same statistic on the simulated
    HQ is 29 % with ``"uniform"``, 12 % with ``"coverage"``. The same random draws as ``"uniform"``,
    mapped onto the half interval;
  - ``"coverage-amplitude"``: the coverage ``c`` as above, weighted by the returned amplitude
    ``albedo / z**2`` of the two surfaces (equal albedo): ``w = c a / (c a + 1 - c)`` with
    ``a = (z_far / z_near)**2``: a phasor sum of the two returns, linearised;

  The renderer samples each pixel's centre, so these laws stand in for the footprint by chance. With
  ``footprint_samples`` = ``n`` > 1 (the default, 4; session 12) the footprint itself is rendered: ``n x n`` rays
  spread over the pixel (:func:`capture.sim.render.footprint_rays`), and a pixel is flying where its footprint's
  depths span more than ``flying_jump_m`` (every such pixel, not a ``flying_fraction`` of the 3x3 jumps). Its depth
  is then the linearised phasor sum of the footprint's returns (:func:`footprint_depth`): the mean of the
  footprint's depths (``"coverage"``; with two surfaces exactly ``c z_near + (1 - c) z_far``, ``c`` the covered
  share), or their mean weighted by the amplitude ``1 / z**2`` (``"coverage-amplitude"``); rays that meet nothing
  return nothing. ``"uniform"`` keeps its random weight between the footprint's nearest and farthest depth. The
  random draws are those of the point-sampled model, so the rest of a session's sensor noise is unchanged.

  Why: a surface thinner than one pixel step (a slit between limbs, a concave corner) vanishes between point
  samples without a trace, while a real time-of-flight pixel integrates its footprint and reads a mix there; the
  warped reference then carries the wrong surface across it with nothing to flag it (``docs/reference_edges.md``,
  session 12). On the Azure Kinect capture's 0.1-0.2 m jumps 3.2 % [0, 7.8 %] of the far-side mixes read nearer
  than the midpoint (session 10's statistic); the rendered footprint gives 3.5 % [1.2, 6.8 %] on the demo
  session's HQ, the point-sampled coverage law 12.6 % [10.7, 14.6 %]. ``n`` = 4: with 3 the demo's reference keeps 2-4
  pixels off by more than 0.3 m that 4 and 5 (0-1) do not (structures a third of a pixel wide);

  and a ``flying_invalid_fraction`` of the flying pixels across a jump over ``flying_invalid_jump_m``
  is invalidated instead (a depth engine that detects mixed signals, as the Azure Kinect's does: on
  the real capture, at jumps > 0.2 m, 54 % of the edge band is invalid and 0.7 % of its valid pixels
  lie between the two sides, while at 0.1-0.2 m 1 % is invalid; session 10, ``simtof.md``; 0 by
  default: no draw, the random stream unchanged);
* ``correlation_px`` (0 = white): the noise blurred by a Gaussian of that many pixels (unit variance kept);
  ``outlier_fraction`` as for stereo;
* no measurement where the returned amplitude ``albedo / z**2`` is below ``min_amplitude``
  (dark surfaces, far away) or outside ``[min_depth_m, max_depth_m]``.

Both models list their parameters in ``to_dict()``, which the simulator writes to
``session.json`` (``sensors.X.noise``) and ``truth/truth.json``.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

import cv2
import numpy as np

from capture.sim.errors import SimulationError
from capture.sim.kernels import footprint_reduce


@dataclass(frozen=True)
class StereoNoise:
    """Active-stereo depth noise; see the module docstring for the model."""

    baseline_m: float = 0.055
    subpixel_px: float = 0.08
    disparity_step_px: float = 1.0 / 32.0
    correlation_px: float = 1.0
    edge_threshold_px: float = 1.0
    edge_invalid_prob: float = 0.7
    texture_window_px: int = 7
    min_contrast: float = 0.012
    min_luminance: float = 0.06
    random_invalid_fraction: float = 0.002
    min_depth_m: float = 0.3
    max_depth_m: float = 10.0
    noise_floor_m: float = 0.0
    outlier_fraction: float = 0.0
    depth_offset_m: float = 0.0
    disparity_offset_px: float = 0.0
    model: str = "stereo"

    def to_dict(self) -> dict:
        d = asdict(self)
        d["sigma_z"] = "z**2 * subpixel_px / (f_px * baseline_m), applied in disparity, quantised to disparity_step_px"
        return d

    def sigma_z(self, z_m: np.ndarray | float, focal_px: float, *, with_quantisation: bool = True):
        """Predicted standard deviation of depth (m) at depth ``z_m`` (first order).

        >>> round(float(StereoNoise().sigma_z(1.0, 600.0, with_quantisation=False)) * 1000, 3)
        2.424
        """
        s = self.subpixel_px if not with_quantisation else np.hypot(self.subpixel_px, self.disparity_step_px / np.sqrt(12))
        return np.asarray(z_m) ** 2 * s / (focal_px * self.baseline_m)


#: How a time-of-flight flying pixel weighs the near and far surface (module docstring).
FLYING_MIXES = ("uniform", "coverage", "coverage-amplitude")


@dataclass(frozen=True)
class TofNoise:
    """Time-of-flight depth noise; see the module docstring for the model."""

    sigma0_m: float = 0.0005
    sigma_slope: float = 0.001
    z0_m: float = 0.5
    flying_jump_m: float = 0.05
    flying_fraction: float = 0.5
    flying_mix: str = "coverage"
    flying_invalid_fraction: float = 0.0
    flying_invalid_jump_m: float = 0.2
    min_amplitude: float = 0.003
    min_depth_m: float = 0.5
    max_depth_m: float = 8.0
    correlation_px: float = 0.0
    outlier_fraction: float = 0.0
    footprint_samples: int = 4
    model: str = "tof"

    def __post_init__(self) -> None:
        if self.flying_mix not in FLYING_MIXES:
            raise SimulationError(f"flying_mix {self.flying_mix!r} is not one of {', '.join(FLYING_MIXES)}")
        if int(self.footprint_samples) != self.footprint_samples or self.footprint_samples < 0:
            raise SimulationError(f"footprint_samples {self.footprint_samples!r} is not a whole number >= 0")

    def to_dict(self) -> dict:
        d = asdict(self)
        d["sigma_z"] = "sigma0_m + sigma_slope * max(z - z0_m, 0)"
        return d

    def sigma_z(self, z_m):
        """Standard deviation of depth (m) at depth ``z_m``.

        >>> round(float(TofNoise().sigma_z(2.0)) * 1000, 3)
        2.0
        """
        return self.sigma0_m + self.sigma_slope * np.maximum(np.asarray(z_m, dtype=np.float64) - self.z0_m, 0.0)


# ----------------------------------------------------------------------------- measured profiles
#: Noise models measured on real captures (``depthbench bench diagnose``, issue 13), with provenance;
#: written by ``python -m bench.diagnose.profiles``.
PROFILES_PATH = Path(__file__).with_name("sensor_profiles.json")


def profile_names() -> list[str]:
    """Names of the measured sensor profiles (e.g. ``D415``, ``D435``, ``Azure Kinect``, ``Kinect v1``)."""
    return list(_profiles())


def sensor_profile(name: str, *, focal_px: float | None = None) -> StereoNoise | TofNoise:
    """The noise model of a real sensor as measured on its capture (see ``sensor_profiles.json``).

    The stored parameters are in the sensor's native depth pixels (the matcher's focal length
    :func:`profile_focal_px`, e.g. 639.04 px for the D435 at 1280x720); its geometry
    (``baseline_m``) is part of the profile. ``focal_px``: the focal length (px) of the simulated
    depth image the model will act on; the pixel parameters are then converted to its pixels
    (:func:`in_pixels` with ``focal_px / profile_focal_px(name)``), which keeps the depth error
    (``z**2 subpixel_px / (f B)``), the quantisation step in depth and the angular correlation
    of the real sensor. None: native pixels.
    """
    entry = _profile_entry(name)
    cls = TofNoise if entry["model"] == "tof" else StereoNoise
    known = {f.name for f in fields(cls)}
    noise = cls(**{k: v for k, v in entry["params"].items() if k in known and k != "model"})
    return noise if focal_px is None else in_pixels(noise, float(focal_px) / profile_focal_px(name))


#: The focal lengths (px) the built-in models' pixel parameters are given in: the rigs' LQ stereo
#: camera (640x480, fx 600 px) and HQ time-of-flight depth camera (512x424, fx 365 px) at scale 1.
DEFAULT_NATIVE_FOCAL_PX = {"stereo": 600.0, "tof": 365.0}


def sensor_noise(model: str, *, focal_px: float, profile: str | None = None) -> StereoNoise | TofNoise:
    """The noise of a simulated ``model`` (``"stereo"`` / ``"tof"``) sensor whose depth image has
    focal length ``focal_px``: the measured ``profile`` (:func:`sensor_profile`) or, with None, the
    built-in model (``StereoNoise()`` / ``TofNoise()``, native to :data:`DEFAULT_NATIVE_FOCAL_PX`).
    Either way the pixel parameters are converted from their native focal length with
    :func:`in_pixels`, so a smaller image (the simulator's ``scale``) keeps the sensor's depth error,
    quantisation step in depth and angular correlation.

    >>> n = sensor_noise("stereo", focal_px=150.0)   # the LQ camera at scale 0.25
    >>> n.subpixel_px, n.correlation_px, n.texture_window_px
    (0.02, 0.25, 3)
    """
    if profile is not None:
        return sensor_profile(profile, focal_px=focal_px)
    if model not in DEFAULT_NATIVE_FOCAL_PX:
        raise SimulationError(f"noise model {model!r} is not one of {', '.join(DEFAULT_NATIVE_FOCAL_PX)}")
    noise = TofNoise() if model == "tof" else StereoNoise()
    return in_pixels(noise, float(focal_px) / DEFAULT_NATIVE_FOCAL_PX[model])


def profile_focal_px(name: str) -> float:
    """The native focal length (px) of profile ``name``: the pixels its parameters are given in."""
    entry = _profile_entry(name)
    focal = entry.get("native_focal_px")
    if not (isinstance(focal, (int, float)) and focal > 0):
        raise SimulationError(f"sensor profile {name!r}: no native_focal_px in {PROFILES_PATH.name}")
    return float(focal)


def in_pixels(noise: StereoNoise | TofNoise, factor: float) -> StereoNoise | TofNoise:
    """``noise`` for an image whose pixels are ``factor`` of the model's (``factor`` = new focal
    length / old focal length, e.g. 0.25 for a quarter-size image).

    Disparities scale with the focal length, so the disparity noise (``subpixel_px``), its step
    and offset, the edge threshold (a disparity range) scale by ``factor``; so do the lengths in
    pixels (``correlation_px``, ``texture_window_px``: rounded to an odd size, at least 3). Depth
    and luminance parameters are unchanged; so is the depth error ``z**2 subpixel_px / (f B)``.

    >>> n = in_pixels(StereoNoise(subpixel_px=0.08, correlation_px=2.0), 0.5)
    >>> n.subpixel_px, n.disparity_step_px, n.correlation_px, n.texture_window_px
    (0.04, 0.015625, 1.0, 3)
    """
    if not factor > 0:
        raise SimulationError(f"pixel factor {factor} must be positive")
    if isinstance(noise, TofNoise):
        return replace(noise, correlation_px=noise.correlation_px * factor)
    window = max(3, 2 * int(round((noise.texture_window_px * factor - 1) / 2)) + 1)
    return replace(noise, subpixel_px=noise.subpixel_px * factor, disparity_step_px=noise.disparity_step_px * factor,
                   disparity_offset_px=noise.disparity_offset_px * factor,
                   edge_threshold_px=noise.edge_threshold_px * factor, correlation_px=noise.correlation_px * factor,
                   texture_window_px=window)


def _profile_entry(name: str) -> dict:
    profiles = _profiles()
    if name not in profiles:
        raise SimulationError(f"sensor profile {name!r} is unknown (known: {', '.join(profiles) or 'none'})")
    return profiles[name]


def _profiles() -> dict:
    try:
        return json.loads(PROFILES_PATH.read_text())
    except FileNotFoundError:
        return {}


# ----------------------------------------------------------------------------- helpers
def correlated_normal(shape: tuple[int, int], sigma_px: float, rng: np.random.Generator) -> np.ndarray:
    """A stationary Gaussian field of unit variance, correlated by a Gaussian of ``sigma_px``.

    >>> f = correlated_normal((200, 300), 1.5, np.random.default_rng(0))
    >>> f.shape, abs(float(f.std()) - 1.0) < 0.05
    ((200, 300), True)
    """
    if sigma_px <= 0:
        return rng.standard_normal(shape, dtype=np.float32)
    r = int(np.ceil(3 * sigma_px))
    k = cv2.getGaussianKernel(2 * r + 1, sigma_px).astype(np.float64)
    gain = float((k ** 2).sum())  # std of the separable blur of unit white noise
    white = rng.standard_normal((shape[0] + 2 * r, shape[1] + 2 * r), dtype=np.float32)
    field = cv2.sepFilter2D(white, -1, k, k, borderType=cv2.BORDER_ISOLATED)
    return field[r:-r, r:-r] / np.float32(gain)


def occluded_in_right(x_right_px: np.ndarray) -> np.ndarray:
    """Left-image pixels the right camera of a rectified pair cannot see (scanline test).

    ``x_right_px`` ``(H, W)`` is the column at which each left pixel's surface point appears in
    the right image (``u - d`` for an undistorted pair; NaN where there is no surface). A point is
    hidden when a pixel to its right in the left image lands at or left of it in the right image:
    the occluder lies on the segment between the point and the right camera, and that segment
    projects onto the same row to the right. This equals casting rays from the right camera,
    except for occluders outside the left image.

    >>> occluded_in_right(np.array([[0.0, 1.0, 2.0, 3.0, 1.5, 2.5]])).tolist()
    [[False, False, True, True, False, False]]
    """
    r = np.where(np.isfinite(x_right_px), x_right_px, np.inf)
    m = np.minimum.accumulate(r[:, ::-1], axis=1)[:, ::-1]
    after = np.concatenate([m[:, 1:], np.full((r.shape[0], 1), np.inf)], axis=1)
    return np.isfinite(r) & (after < r - 1e-3)


def _local_range(img: np.ndarray) -> np.ndarray:
    k = np.ones((3, 3), np.uint8)
    return cv2.dilate(img, k) - cv2.erode(img, k)


def _local_std(img: np.ndarray, window: int) -> np.ndarray:
    mean = cv2.blur(img, (window, window))
    mean2 = cv2.blur(img * img, (window, window))
    return np.sqrt(np.maximum(mean2 - mean * mean, 0.0))


# ----------------------------------------------------------------------------- stereo
@dataclass
class NoisyDepth:
    """A noisy depth image ``(H, W)`` float32 metres (NaN = none) and why pixels are missing."""

    depth: np.ndarray
    invalid: dict[str, np.ndarray]


def stereo_depth(z_true: np.ndarray, ray_x: np.ndarray, luminance: np.ndarray, *, noise: StereoNoise,
                 fx: float, cx: float, rng: np.random.Generator) -> NoisyDepth:
    """Simulate the stereo depth of the left (depth-origin) camera.

    Args:
        z_true: ``(H, W)`` float32 true z-depth in metres, NaN where no surface.
        ray_x: ``(H, W)`` x/z of each pixel's viewing ray in the camera frame (undistorted).
        luminance: ``(H, W)`` float32 shaded luminance in [0, 1] seen by the left camera.
        fx, cx: focal length and principal point (px) of the depth camera.
    Returns:
        :class:`NoisyDepth` with depth in metres and masks ``occlusion``, ``edge``,
        ``texture``, ``range``, ``random``.
    """
    fB = fx * noise.baseline_m
    valid = np.isfinite(z_true) & (z_true > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        disp = np.where(valid, fB / z_true, 0.0).astype(np.float32)
    x_right = np.where(valid, fx * (ray_x - noise.baseline_m / z_true) + cx, np.nan)
    occl = occluded_in_right(x_right) | (valid & (x_right < -0.5))
    edge = (_local_range(disp) > noise.edge_threshold_px) & (rng.random(z_true.shape) < noise.edge_invalid_prob)
    lum = luminance.astype(np.float32)
    texture = (lum < noise.min_luminance) | (_local_std(lum, noise.texture_window_px) < noise.min_contrast)
    rand = rng.random(z_true.shape) < noise.random_invalid_fraction
    d = disp + np.float32(noise.subpixel_px) * correlated_normal(z_true.shape, noise.correlation_px, rng)
    if noise.disparity_offset_px:
        d = d + np.float32(noise.disparity_offset_px)
    step = noise.disparity_step_px
    d = np.round(d / step) * step if step > 0 else d
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (fB / d).astype(np.float32)
    z = _measured_extras(z, valid, noise, rng)
    rng_bad = valid & ~((d > 0) & (z >= noise.min_depth_m) & (z <= noise.max_depth_m))
    bad = ~valid | occl | edge | texture | rand | rng_bad
    z[bad] = np.nan
    return NoisyDepth(z, {"occlusion": occl, "edge": edge & valid, "texture": texture & valid, "range": rng_bad,
                          "random": rand & valid})


def _measured_extras(z: np.ndarray, valid: np.ndarray, noise, rng: np.random.Generator) -> np.ndarray:
    """The diagnosed effects on measured depth: floor noise, constant offset, far outliers (none
    drawn when off, so that default sensors keep their random streams)."""
    floor = getattr(noise, "noise_floor_m", 0.0)
    if floor:
        z = z + np.float32(floor) * correlated_normal(z.shape, getattr(noise, "correlation_px", 0.0), rng)
    if getattr(noise, "depth_offset_m", 0.0):
        z = z + np.float32(noise.depth_offset_m)
    if noise.outlier_fraction:
        out = valid & (rng.random(z.shape) < noise.outlier_fraction)
        z = np.where(out, rng.uniform(noise.min_depth_m, noise.max_depth_m, z.shape), z)
    return z.astype(np.float32)


# ----------------------------------------------------------------------------- time of flight
def flying_weight(z: np.ndarray, z_near: np.ndarray, z_far: np.ndarray, u: np.ndarray, *, mix: str) -> np.ndarray:
    """The near surface's weight ``w`` of a mixed pixel of true depth ``z`` between ``z_near`` and
    ``z_far`` (its 3x3 window's), from uniform draws ``u`` in [0, 1), by ``mix`` (module docstring)."""
    if mix == "uniform":
        return u
    own_near = (z - z_near) <= (z_far - z)
    c = np.where(own_near, 0.5 + 0.5 * u, 0.5 * u).astype(np.float32)
    if mix == "coverage":
        return c
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(z_near > 0, np.square(z_far / z_near), 1.0).astype(np.float32)
    return (c * a / (c * a + 1 - c)).astype(np.float32)


def footprint_depth(footprint: np.ndarray, *, mix: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What a time-of-flight pixel reads from the depths ``footprint`` ``(H, W, S)`` (metres, NaN = the ray met
    nothing) of ``S`` rays over its footprint: ``(z, z_near, z_far)``, each ``(H, W)`` float32: the linearised
    phasor sum of the returns (``"coverage"``: their mean; ``"coverage-amplitude"``: weighted by the amplitude
    ``1 / z**2``; ``"uniform"``: the mean, unused) and the nearest and farthest depth (NaN where nothing returns).

    Computed by the compiled kernel :func:`capture.sim.kernels.footprint_reduce`.

    >>> fp = np.array([[[1.0, 1.0, 1.0, 3.0]]], np.float32)  # a quarter of the footprint on a far surface
    >>> [round(float(v[0, 0]), 3) for v in footprint_depth(fp, mix="coverage")]
    [1.5, 1.0, 3.0]
    >>> round(float(footprint_depth(fp, mix="coverage-amplitude")[0][0, 0]), 3)  # 3 x 1 + 3 / 9, over 3 + 1 / 9
    1.071
    """
    H, W = footprint.shape[:2]
    z, near, far = (np.empty((H, W), np.float32) for _ in range(3))
    footprint_reduce(np.ascontiguousarray(footprint, np.float32), mix == "coverage-amplitude", z, near, far)
    return z, near, far


def _point_mix(zf, valid, u_flying, u_weight, *, noise: TofNoise, far: np.float32):
    """The point-sampled model's flying pixels (a ``flying_fraction`` of the pixels of 3x3 jumps, drawn by
    ``u_flying``) and their mixes (weights from ``u_weight``): ``(flying, z_near, z_far, depth)``, each ``(H, W)``."""
    k = np.ones((3, 3), np.uint8)
    z_near, z_far = cv2.erode(zf, k), cv2.dilate(zf, k)
    flying = valid & (z_far - z_near > noise.flying_jump_m) & (u_flying < noise.flying_fraction)
    z_far = np.minimum(z_far, far / 2)
    w = flying_weight(zf, z_near, z_far, u_weight, mix=noise.flying_mix)
    return flying, z_near, z_far, np.where(flying, w * z_near + (1 - w) * z_far, zf)


def _footprint_mix(zf, valid, footprint: np.ndarray, u_weight, *, noise: TofNoise):
    """The footprint model's flying pixels (every footprint whose depths span a jump) and their depth (module
    docstring; ``"uniform"`` weighs by ``u_weight``): ``(flying, z_near, z_far, depth)``, each ``(H, W)``."""
    z_sum, z_near, z_far = footprint_depth(footprint, mix=noise.flying_mix)
    flying = valid & (z_far - z_near > noise.flying_jump_m)
    z = u_weight * z_near + (1 - u_weight) * z_far if noise.flying_mix == "uniform" else z_sum
    return flying, z_near, z_far, np.where(flying, z, zf)


def tof_depth(z_true: np.ndarray, albedo: np.ndarray, *, noise: TofNoise, rng: np.random.Generator,
              footprint: np.ndarray | None = None) -> NoisyDepth:
    """Simulate a time-of-flight depth image.

    Args:
        z_true: ``(H, W)`` float32 true z-depth in metres at the pixel centres, NaN where no surface.
        albedo: ``(H, W)`` float32 surface reflectance (luminance of the albedo) in [0, 1].
        footprint: ``(H, W, S)`` float32 depths of ``S`` rays over each pixel's footprint (module docstring;
            :func:`capture.sim.render.footprint_rays`), or None: the point-sampled model.
    Returns:
        :class:`NoisyDepth` with masks ``flying``, ``dark``, ``range``.
    """
    valid = np.isfinite(z_true)
    far = np.float32(noise.max_depth_m * 2)
    zf = np.where(valid, z_true, far).astype(np.float32)
    # both models draw the same two fields, so the rest of a session's noise does not depend on the model
    u_flying, u_weight = rng.random(z_true.shape), rng.random(z_true.shape, dtype=np.float32)
    if footprint is None:
        flying, z_near, z_far, z_mixed = _point_mix(zf, valid, u_flying, u_weight, noise=noise, far=far)
    else:
        flying, z_near, z_far, z_mixed = _footprint_mix(zf, valid, footprint, u_weight, noise=noise)
    sigma = noise.sigma_z(z_mixed).astype(np.float32)
    n = correlated_normal(z_true.shape, noise.correlation_px, rng) if noise.correlation_px else \
        rng.standard_normal(z_true.shape, dtype=np.float32)
    z = _measured_extras(z_mixed + sigma * n, valid, noise, rng)
    with np.errstate(divide="ignore", invalid="ignore"):
        dark = valid & (albedo / np.square(zf) < noise.min_amplitude)
    out_of_range = valid & ((z < noise.min_depth_m) | (z > noise.max_depth_m))
    dropped = np.zeros(z_true.shape, bool)
    if noise.flying_invalid_fraction:
        dropped = flying & (z_far - z_near > noise.flying_invalid_jump_m) & \
            (rng.random(z_true.shape) < noise.flying_invalid_fraction)
    z[~valid | dark | out_of_range | dropped] = np.nan
    return NoisyDepth(z.astype(np.float32), {"flying": flying & ~dark, "dark": dark, "range": out_of_range})
