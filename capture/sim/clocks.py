"""Per-sensor clocks: frame rate, offsets, drift, jitter and dropped frames (pure numpy).

Every quantity is an integer number of microseconds except rates. For one sensor, frame
``k = 0, 1, ...`` (frame number ``first_frame_number + k``) is exposed when the sensor's own
oscillator reads ``phase_us + k * period_us``, i.e. at scene time::

    scene_time_us[k]  = rint((phase_us + k * period_us) / device_rate)
    device_timestamp  = device_offset_us + rint(device_rate * scene_time_us)
    host_timestamp    = host_offset_us + rint(host_rate * scene_time_us) + host_jitter_us[k]

with ``period_us = 1e6 / fps``, ``device_rate = 1 + device_drift_ppm * 1e-6``, ``host_rate =
1 + host_drift_ppm * 1e-6`` and ``host_jitter_us[k]`` uniform in ``[-host_jitter_bound_us,
+host_jitter_bound_us]`` (recorded per frame in ``truth/<sensor>/frames.csv``). Frames are
dropped independently with probability ``drop_rate``; a dropped frame keeps its number, so
the frame numbers that remain have gaps. A delivered frame (not the first) is, with probability
``duplicate_rate``, a *duplicate*: it carries the image of the frame delivered before it (same
content, hence same bytes) under its own number and stamps; its ``scene_time_us`` is then the
scene time of that content and ``source_frame_number`` names the frame it copies.

How far apart in scene time the LQ and HQ frames fall (the *frame phase*, what a time-synchronised
pair of frames still differs by) comes from the two sensors' ``phase_us``: drawn with the seed, or
set with ``frame_phase_us`` in :func:`draw_clocks`. The time shift moves stamps, not exposures.

Host timestamps are what alignment uses (``time_base: "host"``): the *host* clock of a sensor
is the clock of the computer that received its frames. The reference sensor (HQ, or ``view0``
without one) has ``host_rate = 1``; another sensor X is offset by ``host_offset_us[X] -
host_offset_us[ref]`` and drifts by its ``host_drift_ppm``, so an instant stamped ``t`` by the
reference is stamped ``t + Delta(t)`` by X with ``Delta(t) = a + b (t - t0)``, ``a = time_shift_us``,
``b = host_drift_ppm * 1e-6``, ``t0 = host_offset_us[ref]`` (the reference's host stamp of scene
time 0). Device timestamps are in each device's own domain (offset and crystal drift of its own).

Example:
    >>> c = Clock(fps=30.0, first_frame_number=1, phase_us=0.0, device_offset_us=0, device_drift_ppm=0.0,
    ...           host_offset_us=1000, host_drift_ppm=0.0, host_jitter_bound_us=0, drop_rate=0.0)
    >>> s = frame_schedule(c, seconds=0.1, rng=np.random.default_rng(0))
    >>> s.frame_number.tolist(), s.scene_time_us.tolist(), s.host_timestamp_us.tolist()
    ([1, 2, 3], [0, 33333, 66667], [1000, 34333, 67667])
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

#: Default bound of the host arrival jitter (uniform, microseconds): small against a 33 ms
#: period, so nearest-timestamp association (SSDD eq. 28) stays unambiguous.
DEFAULT_JITTER_US = 1000
#: Drawn time shifts lie within +-this (microseconds). SSDD searches +-60 ms, as align does
#: (``align.time_shift.DEFAULT_RANGE_US``), and align refuses a best shift on the edge of its range (the true
#: one may lie outside): a shift drawn over the whole range failed there when its estimate erred towards the
#: edge (session 7, seed 26: drawn -58.9 ms, estimated -59.5 +- 0.7 ms, 0.49 ms from the end; about 2-3 % of
#: seeds). So the draw keeps 5 ms inside the search range (a few times the estimates' errors, 0.4-1.1 ms).
DEFAULT_MAX_SHIFT_US = 55_000
#: the range of the random integer behind a drawn shift: the same random numbers as when shifts were drawn
#: over +-60 ms, so every other draw of a seed is unchanged, and so is every shift already inside the margin
_SHIFT_DRAW_US = 60_000


@dataclass(frozen=True)
class Clock:
    """One sensor's clock model (see the module docstring for the formulas)."""

    fps: float
    first_frame_number: int
    phase_us: float
    device_offset_us: int
    device_drift_ppm: float
    host_offset_us: int
    host_drift_ppm: float
    host_jitter_bound_us: int
    drop_rate: float
    duplicate_rate: float = 0.0

    @property
    def period_us(self) -> float:
        return 1e6 / self.fps

    @property
    def device_rate(self) -> float:
        return 1.0 + self.device_drift_ppm * 1e-6

    @property
    def host_rate(self) -> float:
        return 1.0 + self.host_drift_ppm * 1e-6

    def scene_time_us(self, k: np.ndarray) -> np.ndarray:
        """Scene time (µs, int64) of the frames with index ``k`` (0 = first frame)."""
        return np.rint((self.phase_us + np.asarray(k, np.float64) * self.period_us) / self.device_rate).astype(np.int64)

    def device_timestamp_us(self, scene_time_us: np.ndarray) -> np.ndarray:
        return self.device_offset_us + np.rint(self.device_rate * np.asarray(scene_time_us, np.float64)).astype(np.int64)

    def host_timestamp_us(self, scene_time_us: np.ndarray, jitter_us: np.ndarray | int = 0) -> np.ndarray:
        return (self.host_offset_us + np.rint(self.host_rate * np.asarray(scene_time_us, np.float64)).astype(np.int64)
                + np.asarray(jitter_us, np.int64))

    def to_dict(self) -> dict:
        d = asdict(self)
        d["period_us"] = self.period_us
        return d


@dataclass(frozen=True)
class Schedule:
    """The frames one sensor delivers (dropped ones removed), all arrays ``(N,)`` int64.

    ``scene_time_us`` is the instant whose content the frame carries (for a duplicate, that of
    the frame it copies; its stamps are those of its own slot); ``source_frame_number`` the frame
    whose content it is (itself unless duplicated).
    """

    frame_number: np.ndarray
    scene_time_us: np.ndarray
    device_timestamp_us: np.ndarray
    host_timestamp_us: np.ndarray
    host_jitter_us: np.ndarray
    dropped_frame_numbers: np.ndarray
    source_frame_number: np.ndarray | None = None

    @property
    def duplicated_frame_numbers(self) -> np.ndarray:
        if self.source_frame_number is None:
            return np.zeros(0, np.int64)
        return self.frame_number[self.source_frame_number != self.frame_number]

    def __len__(self) -> int:
        return len(self.frame_number)


def frame_schedule(clock: Clock, *, seconds: float, rng: np.random.Generator) -> Schedule:
    """Every frame whose scene time lies in ``[0, seconds)``; drops, jitter and duplicates drawn from ``rng``
    (duplicates from a generator of their own, so that switching them on changes nothing else)."""
    n = int(np.ceil(seconds * 1e6 * clock.device_rate / clock.period_us)) + 2
    k = np.arange(n)
    t = clock.scene_time_us(k)
    keep = t < round(seconds * 1e6)
    k, t = k[keep], t[keep]
    drop = rng.random(len(k)) < clock.drop_rate
    if drop.all() and len(drop):
        drop[0] = False
    jitter = rng.integers(-clock.host_jitter_bound_us, clock.host_jitter_bound_us + 1, len(k)).astype(np.int64)
    fn = clock.first_frame_number + k.astype(np.int64)
    kept = ~drop
    fn_k, t_k = fn[kept], t[kept]
    source, content_t = fn_k.copy(), t_k.copy()
    if clock.duplicate_rate > 0 and fn_k.size > 1:
        dup = np.random.default_rng(rng.integers(0, 2**63)).random(fn_k.size) < clock.duplicate_rate
        dup[0] = False
        for i in np.flatnonzero(dup):  # a copy of a copy carries the original's content
            source[i], content_t[i] = source[i - 1], content_t[i - 1]
    return Schedule(fn_k, content_t, clock.device_timestamp_us(t_k), clock.host_timestamp_us(t_k, jitter[kept]),
                    jitter[kept], fn[drop], source)


def draw_shift_us(rng: np.random.Generator) -> int:
    """A sensor's time shift, microseconds, uniform within +-``DEFAULT_MAX_SHIFT_US`` (inside align's +-60 ms
    search range with a margin).

    One random integer is drawn from ``rng`` over +-60 ms, as before the margin was kept. A draw inside the
    margin is the shift, so every such seed simulates the session it always did (scaling every draw by 55/60
    moved the demo's four-view rig, seed 2001, under the feature fit's minimum of matches). A draw outside it
    (about 8 %) is replaced by a uniform one from a generator seeded by that draw, which leaves ``rng``'s
    stream, and so the rest of the seed, untouched (rejection sampling: the result is uniform).
    """
    shift = int(rng.integers(-_SHIFT_DRAW_US, _SHIFT_DRAW_US + 1))
    if abs(shift) <= DEFAULT_MAX_SHIFT_US:
        return shift
    redraw = np.random.default_rng(abs(shift) * 2 + (shift < 0))
    return int(redraw.integers(-DEFAULT_MAX_SHIFT_US, DEFAULT_MAX_SHIFT_US + 1))


def draw_clocks(sensors: dict[str, float], *, reference: str, target: str | None, rng: np.random.Generator,
                time_shift_us: int | None = None, drift_ppm: float = 0.0, drop_rate: float = 0.0,
                jitter_bound_us: int = DEFAULT_JITTER_US, duplicate_rate: float = 0.0,
                frame_phase_us: float | None = None) -> dict[str, Clock]:
    """Draw a clock for each sensor (``{sensor: fps}``).

    ``reference`` gets host offset ``t0`` (an epoch-like time) and no host drift; ``target`` (the LQ
    sensor the effects act on) is shifted by ``time_shift_us`` (:func:`draw_shift_us` if None) and
    drifts by ``drift_ppm`` and duplicates frames at ``duplicate_rate``; other sensors get their own
    drawn shift. ``frame_phase_us``: the target's frames are exposed this long after the
    reference's (scene time: the target's ``phase_us`` is the reference's plus this, modulo the
    target's period, so at equal frame rates every target frame falls ``frame_phase_us`` mod one
    period after a reference frame, up to the devices' drift of +-20 ppm); ``None``: each phase is
    drawn uniformly within one period (the same random numbers are drawn either way).
    """
    t0 = 1_700_000_000_000_000 + int(rng.integers(0, 365 * 86_400 * 10**6))
    clocks = {}
    for sid, fps in sensors.items():
        shift = draw_shift_us(rng)  # always drawn: same stream
        if sid == reference:
            shift = 0
        elif sid == target and time_shift_us is not None:
            shift = int(time_shift_us)
        clocks[sid] = Clock(
            fps=float(fps), first_frame_number=int(rng.integers(1, 1000)),
            phase_us=float(rng.uniform(0, 1e6 / fps)), device_offset_us=int(rng.integers(10**6, 10**10)),
            device_drift_ppm=float(np.round(rng.uniform(-20, 20), 3)), host_offset_us=t0 + shift,
            host_drift_ppm=float(drift_ppm) if sid == target else 0.0, host_jitter_bound_us=int(jitter_bound_us),
            drop_rate=float(drop_rate), duplicate_rate=float(duplicate_rate) if sid == target else 0.0)
    if frame_phase_us is not None and target in clocks and reference in clocks:
        c = clocks[target]
        phase = float(np.mod(clocks[reference].phase_us + float(frame_phase_us), c.period_us))
        clocks[target] = replace(c, phase_us=phase)
    return clocks
