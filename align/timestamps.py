"""Host timestamps with the arrival jitter taken out. Pure numpy, no I/O.

A sensor exposes its frames on a regular clock (one frame every ``1/fps``), but the host stamps
each frame when it *arrives*, with a random delay (USB, driver, scheduler). That jitter (up to
about a millisecond) is noise on every time the alignment computes, and it does not average out
in a handful of probe frames. Because the frame counter is regular, the stamps can be
regularised: a robust straight line ``stamp = a + period * frame_number`` fitted to all frames of
a stream (dropped frames keep their numbers, so gaps are honoured) predicts each frame's stamp
without the jitter. If a single line does not describe the stream (its clock rate wanders, or
the frame numbers are not a clock), a local line over a sliding window of frames is used
instead, and if even that leaves residuals above ``max_rms_us`` the raw stamps are kept.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from align.errors import ShapeError


@dataclass(frozen=True)
class Regularized:
    """Regularised stamps of one stream.

    Attributes:
        stamps_us: ``(N,)`` int64 stamps used from now on (the raw ones if ``method == "raw"``).
        raw_us: ``(N,)`` int64 original stamps.
        method: ``"line"``, ``"local"`` or ``"raw"``.
        jitter_rms_us: RMS of raw minus regularised stamps.
        period_us: fitted frame period (line) or median frame interval.
    """

    stamps_us: np.ndarray
    raw_us: np.ndarray
    method: str
    jitter_rms_us: float
    period_us: float

    def to_dict(self) -> dict:
        return {"method": self.method, "jitter_rms_us": round(float(self.jitter_rms_us), 1),
                "period_us": round(float(self.period_us), 3)}


def _robust_line(x: np.ndarray, y: np.ndarray, iterations: int = 3):
    keep = np.ones(x.size, bool)
    for _ in range(iterations):
        A = np.stack([np.ones(keep.sum()), x[keep]], axis=1)
        coef, *_ = np.linalg.lstsq(A, y[keep], rcond=None)
        r = y - (coef[0] + coef[1] * x)
        s = 1.4826 * np.median(np.abs(r[keep])) + 1.0
        keep = np.abs(r) < 4 * s
    return coef, r


def _local_line(x: np.ndarray, y: np.ndarray, half: int) -> np.ndarray:
    """Value at each x of the least-squares line through the samples within +-half positions."""
    n = x.size
    c = np.concatenate([[0.0], np.cumsum(np.ones(n))])
    cx = np.concatenate([[0.0], np.cumsum(x)])
    cy = np.concatenate([[0.0], np.cumsum(y)])
    cxx = np.concatenate([[0.0], np.cumsum(x * x)])
    cxy = np.concatenate([[0.0], np.cumsum(x * y)])
    lo = np.clip(np.arange(n) - half, 0, n)
    hi = np.clip(np.arange(n) + half + 1, 0, n)
    m = c[hi] - c[lo]
    sx, sy, sxx, sxy = cx[hi] - cx[lo], cy[hi] - cy[lo], cxx[hi] - cxx[lo], cxy[hi] - cxy[lo]
    den = m * sxx - sx * sx
    slope = np.where(den > 0, (m * sxy - sx * sy) / np.where(den > 0, den, 1), 0.0)
    icpt = (sy - slope * sx) / m
    return icpt + slope * x


def regularize(frame_numbers, stamps_us, *, window: int = 61, max_rms_us: float = 3000.0) -> Regularized:
    """Regularise one stream's stamps against its frame numbers (see the module docstring)."""
    f = np.asarray(frame_numbers, np.int64)
    t = np.asarray(stamps_us, np.int64)
    if f.shape != t.shape:
        raise ShapeError(f"frame numbers {f.shape} and stamps {t.shape} differ in shape")
    if t.size < 8 or np.any(np.diff(f) <= 0):
        period = float(np.median(np.diff(t))) if t.size > 1 else 0.0
        return Regularized(t.copy(), t, "raw", 0.0, period)
    x = (f - f[0]).astype(np.float64)
    y = (t - t[0]).astype(np.float64)  # small numbers: no float64 precision loss on epoch stamps
    coef, r_line = _robust_line(x, y)
    rms_line = float(np.sqrt(np.mean(r_line ** 2)))
    fit_local = _local_line(x, y, window // 2)
    rms_local = float(np.sqrt(np.mean((y - fit_local) ** 2)))
    if rms_line <= 1.5 * rms_local + 100.0 and rms_line <= max_rms_us:
        fit, method, rms = coef[0] + coef[1] * x, "line", rms_line
    elif rms_local <= max_rms_us:
        fit, method, rms = fit_local, "local", rms_local
    else:
        return Regularized(t.copy(), t, "raw", 0.0, float(np.median(np.diff(t))))
    stamps = t[0] + np.rint(fit).astype(np.int64)
    return Regularized(stamps, t, method, rms, float(coef[1]))
