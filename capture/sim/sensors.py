"""Turn what a sensor's cameras see into its frames: noisy depth, colour, noise-free truth.

Pure numpy (the ray casting is behind :class:`capture.sim.render.Renderer`). One function per
sensor technology; both return a :class:`SensorFrame`.
"""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from time import perf_counter

import cv2
import numpy as np

from capture.sim.effects import ROLLING_SHUTTER_BAND_MS, SensorEffects
from capture.sim.noise import StereoNoise, TofNoise, stereo_depth, tof_depth
from capture.sim.render import CameraRays, Hits, Renderer, camera_rays, footprint_rays, footprint_samples
from capture.sim.rigs import SensorSpec


@dataclass
class SensorFrame:
    """One frame of one sensor: ``depth`` float32 metres (NaN = none), ``color`` uint8 RGB,
    ``truth_depth`` float32 metres (noise-free, same pixels as ``depth``), invalid-pixel masks."""

    depth: np.ndarray
    color: np.ndarray
    truth_depth: np.ndarray
    invalid: dict[str, np.ndarray]


@dataclass
class SensorCameras:
    """Cached rays of a sensor's depth camera, (unless co-registered) its colour camera, and (a time-of-flight
    sensor that integrates its pixels' footprints, ``TofNoise.footprint_samples`` > 1) its depth pixels' footprints
    (:func:`capture.sim.render.footprint_rays`)."""

    depth: CameraRays
    color: CameraRays | None
    footprint: CameraRays | None = None

    @classmethod
    def of(cls, spec: SensorSpec) -> "SensorCameras":
        """The cameras of ``spec``, posed in the world."""
        n = getattr(spec.noise, "footprint_samples", 0)
        return cls(camera_rays(spec.depth, spec.T_world_depth),
                   None if spec.color_is_depth else camera_rays(spec.color, spec.T_world_color),
                   footprint_rays(spec.depth, spec.T_world_depth, n) if n > 1 else None)


class Timings(dict):
    """Seconds spent per stage, accumulated: ``with timings("raycast"): ...``."""

    @contextmanager
    def __call__(self, stage: str):
        t = perf_counter()
        try:
            yield
        finally:
            self[stage] = self.get(stage, 0.0) + perf_counter() - t


def render_frame(spec: SensorSpec, cams: SensorCameras, renderer: Renderer, t_s: float, *,
                 rng: np.random.Generator, effects: SensorEffects | None = None,
                 timings: Timings | None = None) -> SensorFrame:
    """Render sensor ``spec`` at scene time ``t_s`` seconds, with ``effects`` (depth scale and
    offset, colour rolling shutter; :mod:`capture.sim.effects`) if given.
    ``timings`` gets the seconds spent on noise; the renderer counts its own (``Renderer.stage_s``)."""
    timings = timings if timings is not None else Timings()
    fx = effects or SensorEffects()
    seeds = rng.integers(0, 2**63, size=2)
    hits = renderer.cast(cams.depth, t_s, noise_seed=int(seeds[0]), noise_dn=spec.color_noise_dn)
    # a ray cast (the renderer counts its time)
    footprint = _footprint(renderer, cams, t_s, hits, jump_m=getattr(spec.noise, "flying_jump_m", 0.0))
    with timings("noise"):
        if isinstance(spec.noise, StereoNoise):
            K = cams.depth.intrinsics
            noisy = stereo_depth(hits.z, cams.depth.xy[..., 0], hits.shaded_luminance, noise=spec.noise,
                                 fx=K.fx, cx=K.cx, rng=rng)
        else:
            assert isinstance(spec.noise, TofNoise)
            noisy = tof_depth(hits.z, hits.albedo_luminance, noise=spec.noise, rng=rng, footprint=footprint)
        depth = noisy.depth
        if fx.changes_depth:
            depth = (depth * np.float32(fx.depth_scale) + np.float32(fx.depth_offset_m)).astype(np.float32)
    color_cam, seed = (cams.color, int(seeds[1])) if cams.color is not None else (cams.depth, int(seeds[0]))
    if fx.readout_s > 0:
        color = rolling_shutter_color(renderer, color_cam, t_s, fx.readout_s, noise_seed=seed,
                                      noise_dn=spec.color_noise_dn)
    elif cams.color is not None:
        color = renderer.cast(cams.color, t_s, noise_seed=seed, noise_dn=spec.color_noise_dn).rgb
    else:
        color = hits.rgb
    return SensorFrame(depth, color, hits.z, noisy.invalid)


#: how far (depth pixels) from a pixel whose centre sees a moving part the footprint's rays are cast each frame
FOOTPRINT_REACH_PX = 2


def _footprint(renderer: Renderer, cams: SensorCameras, t_s: float, hits: Hits, *, jump_m: float) -> np.ndarray | None:
    """The depths over each depth pixel's footprint ``(H, W, n * n)``, or None (a point-sampled sensor).

    The rays are cast again only where a footprint can both meet a moving part and span more than ``jump_m``
    (the time-of-flight model's flying-pixel jump; elsewhere the model reads the centre's depth whatever the
    footprint holds): within ``FOOTPRINT_REACH_PX`` of a pixel whose centre ray sees something else than the still
    layer (a moving part), and within one pixel of a pixel whose 3x3 centre rays meet more than one scene part, or
    nothing, or span more than half of ``jump_m``. Outside the first the rays keep the still layer's depths; outside
    the second, inside the moving parts, they take the centre's depth. The simulator's parts are convex and
    thicker than a pixel, so a footprint inside one part's 3x3 centre rays sees that part alone;
    ``tests/capture/test_sim_footprint.py`` checks the result equals the full cast's on the simulator's scenes."""
    if cams.footprint is None:
        return None
    n = cams.footprint.intrinsics.width // cams.depth.intrinsics.width
    still = renderer.still_depth(cams.depth)
    if still is None:
        return footprint_samples(renderer.cast_depth(cams.footprint, t_s), n)
    z = hits.z
    moving = ~((z == still) | (np.isnan(z) & np.isnan(still)))
    reach = cv2.dilate(moving.astype(np.uint8), np.ones((2 * FOOTPRINT_REACH_PX + 1,) * 2, np.uint8)).astype(bool)
    k = np.ones((3, 3), np.uint8)
    zf = np.where(np.isfinite(z), z, np.float32(1e3)).astype(np.float32)  # nothing: a jump to 1 km
    part = hits.part.astype(np.float32)
    edge = (cv2.dilate(zf, k) - cv2.erode(zf, k) > 0.5 * jump_m) | (cv2.dilate(part, k) != cv2.erode(part, k))
    cast = reach & cv2.dilate(edge.astype(np.uint8), k).astype(bool)
    fine = renderer.cast_depth(cams.footprint, t_s, within=np.repeat(np.repeat(cast, n, axis=0), n, axis=1))
    out = footprint_samples(fine, n)
    inside = reach & ~cast  # a moving part's interior: one surface, the centre's depth
    out[inside] = z[inside][:, None]
    return out


def rolling_shutter_color(renderer: Renderer, cam: CameraRays, t_s: float, readout_s: float, *, noise_seed: int,
                          noise_dn: float) -> np.ndarray:
    """A colour image ``(H, W, 3)`` uint8 whose row ``y`` is exposed at ``t_s + readout_s ((y + 0.5) / H - 0.5)``:
    rendered in bands of rows at most ``ROLLING_SHUTTER_BAND_MS`` apart, each band at its middle
    row's instant (the same per-pixel sensor noise as a global-shutter cast)."""
    H = cam.intrinsics.height
    bands = int(min(H, max(1, np.ceil(readout_s * 1e3 / ROLLING_SHUTTER_BAND_MS))))
    edges = np.linspace(0, H, bands + 1).round().astype(int)
    out = None
    for r0, r1 in zip(edges[:-1], edges[1:]):
        if r1 <= r0:
            continue
        t_band = t_s + readout_s * ((r0 + r1) / 2 / H - 0.5)
        rgb = renderer.cast(cam, t_band, noise_seed=noise_seed, noise_dn=noise_dn).rgb
        if out is None:
            out = np.empty_like(rgb)
        out[r0:r1] = rgb[r0:r1]
    return out
