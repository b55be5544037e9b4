"""Turn what a sensor's cameras see into its frames: noisy depth, colour, noise-free truth.

Pure numpy (the ray casting is behind :class:`capture.sim.render.Renderer`). One function per
sensor technology; both return a :class:`SensorFrame`.
"""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from time import perf_counter

import numpy as np

from capture.sim.noise import StereoNoise, TofNoise, stereo_depth, tof_depth
from capture.sim.render import CameraRays, Renderer
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
    """Cached rays of a sensor's depth camera and (unless co-registered) colour camera."""

    depth: CameraRays
    color: CameraRays | None


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
                 rng: np.random.Generator, depth_scale: float = 1.0, timings: Timings | None = None) -> SensorFrame:
    """Render sensor ``spec`` at scene time ``t_s`` seconds (``depth_scale`` multiplies its depth).
    ``timings`` gets the seconds spent on noise; the renderer counts its own (``Renderer.stage_s``)."""
    timings = timings if timings is not None else Timings()
    seeds = rng.integers(0, 2**63, size=2)
    hits = renderer.cast(cams.depth, t_s, noise_seed=int(seeds[0]), noise_dn=spec.color_noise_dn)
    with timings("noise"):
        if isinstance(spec.noise, StereoNoise):
            K = cams.depth.intrinsics
            noisy = stereo_depth(hits.z, cams.depth.xy[..., 0], hits.shaded_luminance, noise=spec.noise,
                                 fx=K.fx, cx=K.cx, rng=rng)
        else:
            assert isinstance(spec.noise, TofNoise)
            noisy = tof_depth(hits.z, hits.albedo_luminance, noise=spec.noise, rng=rng)
        depth = noisy.depth if depth_scale == 1.0 else (noisy.depth * np.float32(depth_scale)).astype(np.float32)
    color = hits.rgb
    if cams.color is not None:
        color = renderer.cast(cams.color, t_s, noise_seed=int(seeds[1]), noise_dn=spec.color_noise_dn).rgb
    return SensorFrame(depth, color, hits.z, noisy.invalid)
