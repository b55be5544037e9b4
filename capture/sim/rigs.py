"""Simulated rigs: which sensors, their cameras, poses, noise models and frame rates.

Pure numpy, no I/O. Conventions as in :mod:`capture.camera`: camera frame x right, y down,
z forward; world frame z up (see :mod:`capture.sim.scene`); ``T_world_cam`` maps camera points
into the world.

Rigs (``RIGS``):

* ``lq-hq`` (SSDD): sensor ``lq``, a RealSense D415-like active stereo camera, depth 640x480
  (fx = 600 px, baseline 55 mm) with colour co-registered to depth (``T_depth_color`` = identity,
  like RealSense's align-to-colour mode); sensor ``hq``, a Kinect v2 / Azure-like time-of-flight
  camera, depth 512x424 (fx = 365 px) with its own 960x540 colour camera 5.2 cm to the side
  (its ``T_depth_color`` is declared in the session). The HQ depth camera sits 12.5 cm to the
  right of the LQ one with a rotation of about 2 degrees.
* ``multiview4`` (DDD): four LQ sensors ``view0..view3`` at the corners of an H-stand
  (1.2 m wide, 1.0 m tall), toed in towards the middle of the room.
* ``multiview4-hq``: the same plus the HQ sensor ``hq`` in the middle of the H.

Sensor profiles (``lq_profile`` / ``hq_profile``): the noise model of a real sensor measured by
``depthbench bench diagnose`` (``capture/sim/sensor_profiles.json``: ``D435``, ``D415``,
``Kinect v1`` for the stereo LQ / view sensors, ``Azure Kinect`` for the time-of-flight HQ one)
replaces the default noise; the cameras (image size, focal length, poses) stay the rig's. The
profile's pixel parameters are native to the real sensor's matcher (``native_focal_px``) and are
converted to the simulated depth image's focal length, scale included
(:func:`capture.sim.noise.sensor_noise`), so the depth error at a given depth is the real
sensor's at any ``scale``. The built-in models are converted the same way from the scale-1
cameras' focal lengths (LQ 600 px, HQ 365 px): at ``scale`` 0.5 the LQ matching noise is 0.04 px
of the 300 px image, the same depth error as 0.08 px at scale 1.

Example:
    >>> rig = build_rig("lq-hq")
    >>> [s.id for s in rig.sensors], rig.reference, rig.target
    (['lq', 'hq'], 'hq', 'lq')
    >>> T = rig.T_dst_src("lq", "hq")
    >>> round(float(np.linalg.norm(T.t)), 3)
    0.126
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from capture.camera import Intrinsics, Transform
from capture.sim.errors import SimulationError
from capture.sim.noise import StereoNoise, TofNoise, profile_focal_px, profile_names, sensor_noise, sensor_profile

RIGS = ("lq-hq", "multiview4", "multiview4-hq")


@dataclass(frozen=True)
class SensorSpec:
    """One simulated sensor: depth camera pose, intrinsics, colour camera, noise, frame rate."""

    id: str
    role: str
    model: str
    technology: str
    depth: Intrinsics
    color: Intrinsics
    T_world_depth: Transform
    T_depth_color: Transform
    noise: StereoNoise | TofNoise
    fps: float
    depth_unit_m: float = 0.001
    color_noise_dn: float = 1.5
    serial: str = ""
    profile: str = ""

    def noise_dict(self) -> dict:
        """The noise model as written to ``session.json`` and ``truth/`` (with the sensor profile
        and its pixel conversion when one is used)."""
        d = self.noise.to_dict() | {"color_noise_dn": self.color_noise_dn}
        if self.profile:
            native = profile_focal_px(self.profile)
            d["profile"] = {"name": self.profile, "native_focal_px": native, "pixel_factor": self.depth.fx / native}
        return d

    @property
    def T_world_color(self) -> Transform:
        return self.T_world_depth @ self.T_depth_color

    @property
    def color_is_depth(self) -> bool:
        """Colour co-registered with depth: one ray cast serves both."""
        return self.T_depth_color.is_close(Transform.identity()) and self.color == self.depth


@dataclass(frozen=True)
class Rig:
    """The sensors of a rig, the reference clock's sensor and the sensor the effects act on."""

    name: str
    sensors: tuple[SensorSpec, ...]
    reference: str
    target: str
    declared_extrinsics: tuple[tuple[str, str], ...] = field(default=())

    def sensor(self, sid: str) -> SensorSpec:
        return next(s for s in self.sensors if s.id == sid)

    def T_dst_src(self, dst: str, src: str) -> Transform:
        """Maps points of ``src``'s depth camera into ``dst``'s depth camera (metres)."""
        return self.sensor(dst).T_world_depth.inverse() @ self.sensor(src).T_world_depth

    def with_sensor(self, spec: SensorSpec) -> "Rig":
        return replace(self, sensors=tuple(spec if s.id == spec.id else s for s in self.sensors))


# ----------------------------------------------------------------------------- poses
def look_at(eye, target, *, up=(0.0, 0.0, 1.0), roll_rad: float = 0.0) -> Transform:
    """``T_world_cam`` of a camera at ``eye`` looking at ``target`` (z up), optionally rolled.

    >>> T = look_at((0, 0, 1), (0, 5, 1))
    >>> T.R.round(6).tolist()
    [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]
    """
    eye, target, up = (np.asarray(a, dtype=np.float64) for a in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z], axis=1)
    c, s = np.cos(roll_rad), np.sin(roll_rad)
    R = R @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return Transform.from_rt(R, eye)


# ----------------------------------------------------------------------------- sensors
def _lq_sensor(sid: str, role: str, pose: Transform, *, fps: float, scale: float, serial: str) -> SensorSpec:
    K = Intrinsics(640, 480, fx=600.0, fy=600.0, cx=321.7, cy=238.4)
    K = K.scaled(round(640 * scale), round(480 * scale)) if scale != 1 else K
    return SensorSpec(sid, role, "Intel RealSense D415 (simulated)", "stereo", K, K, pose, Transform.identity(),
                      sensor_noise("stereo", focal_px=K.fx), float(fps), depth_unit_m=0.001, serial=serial)


#: The HQ sensor's own calibration: its colour camera in its depth camera's frame.
HQ_T_DEPTH_COLOR = Transform.from_rotvec((0.0021, -0.0035, 0.0012), (-0.052, 0.0011, 0.0006))


def _hq_sensor(pose: Transform, *, fps: float, scale: float) -> SensorSpec:
    Kd = Intrinsics(512, 424, fx=365.0, fy=365.0, cx=257.2, cy=208.9)
    Kc = Intrinsics(960, 540, fx=530.0, fy=530.0, cx=478.6, cy=271.3)
    if scale != 1:
        Kd = Kd.scaled(round(512 * scale), round(424 * scale))
        Kc = Kc.scaled(round(960 * scale), round(540 * scale))
    return SensorSpec("hq", "hq", "Kinect v2 / Azure Kinect-like ToF (simulated)", "tof", Kd, Kc, pose,
                      HQ_T_DEPTH_COLOR, sensor_noise("tof", focal_px=Kd.fx), float(fps), depth_unit_m=0.001,
                      serial="SIM-HQ-0001")


#: The HQ depth camera in the LQ depth camera's frame on the lq-hq mount (the truth T_lq_hq).
LQ_T_HQ = Transform.from_rotvec((0.006, -0.031, 0.004), (0.125, 0.011, -0.006))


def build_rig(name: str, *, scale: float = 1.0, lq_fps: float = 30.0, hq_fps: float = 30.0,
              lq_profile: str | None = None, hq_profile: str | None = None) -> Rig:
    """Build rig ``name`` (one of :data:`RIGS`); ``scale`` multiplies every image size (tiny tests).

    ``lq_profile`` / ``hq_profile``: a measured sensor profile (:func:`capture.sim.noise.profile_names`)
    for the LQ / view sensors (stereo) and the HQ sensor (time of flight); None: the default noise.
    """
    if name not in RIGS:
        raise SimulationError(f"--rig: unknown rig {name!r} (choose from {', '.join(RIGS)})")
    if not (0.05 <= scale <= 2.0):
        raise SimulationError(f"--scale: {scale} is outside [0.05, 2]")
    for what, fps in (("--lq-fps", lq_fps), ("--hq-fps", hq_fps)):
        if not (1.0 <= fps <= 120.0):
            raise SimulationError(f"{what}: {fps} is outside [1, 120] frames per second")
    rig = _build_geometry(name, scale=scale, lq_fps=lq_fps, hq_fps=hq_fps)
    for option, profile, role in (("--lq-profile", lq_profile, "stereo"), ("--hq-profile", hq_profile, "tof")):
        if profile is not None:
            rig = _with_profile(rig, profile, option=option, model=role)
    return rig


def _with_profile(rig: Rig, profile: str, *, option: str, model: str) -> Rig:
    """``rig`` with every sensor of noise model ``model`` using the measured profile ``profile``."""
    names = profile_names()
    if profile not in names:
        raise SimulationError(f"{option}: unknown sensor profile {profile!r} (choose from {', '.join(names)})")
    if sensor_profile(profile).model != model:
        fits = [n for n in names if sensor_profile(n).model == model]
        raise SimulationError(f"{option}: profile {profile!r} is not a {model} sensor (choose from {', '.join(fits)})")
    targets = [s for s in rig.sensors if s.noise.model == model]
    if not targets:
        raise SimulationError(f"{option}: rig {rig.name!r} has no {model} sensor")
    for s in targets:
        noise = sensor_noise(model, focal_px=s.depth.fx, profile=profile)
        rig = rig.with_sensor(replace(s, noise=noise, profile=profile, model=f"{profile} profile (simulated)"))
    return rig


def _build_geometry(name: str, *, scale: float, lq_fps: float, hq_fps: float) -> Rig:
    if name == "lq-hq":
        T_world_lq = look_at((0.0, 0.0, 1.3), (0.0, 3.0, 1.0))
        lq = _lq_sensor("lq", "lq", T_world_lq, fps=lq_fps, scale=scale, serial="SIM-LQ-0001")
        hq = _hq_sensor(T_world_lq @ LQ_T_HQ, fps=hq_fps, scale=scale)
        return Rig(name, (lq, hq), reference="hq", target="lq")
    target = (0.0, 2.8, 1.15)
    corners = [(-0.6, 1.75), (0.6, 1.75), (-0.6, 0.75), (0.6, 0.75)]
    views = tuple(_lq_sensor(f"view{i}", "view", look_at((x, 0.0, z), target, roll_rad=0.01 * (i - 1.5)),
                             fps=lq_fps, scale=scale, serial=f"SIM-VIEW-000{i}") for i, (x, z) in enumerate(corners))
    declared = tuple(("view0", f"view{i}") for i in range(1, 4))
    if name == "multiview4":
        return Rig(name, views, reference="view0", target="view1", declared_extrinsics=declared)
    hq = _hq_sensor(look_at((0.0, 0.02, 1.25), target, roll_rad=0.004), fps=hq_fps, scale=scale)
    return Rig(name, views + (hq,), reference="hq", target="view0", declared_extrinsics=declared)
