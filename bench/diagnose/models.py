"""Candidate error models and their selection (pure numpy/scipy, no I/O).

Each quantity is measured in bins (:mod:`bench.diagnose.stats`) with a standard error, then
every candidate model is fitted by weighted least squares and compared two ways:

* the Akaike information criterion with the small-sample correction,
  ``AICc = chi2 + 2k + 2k(k+1)/(n-k-1)`` (Gaussian errors of known scale, ``chi2`` the
  weighted residual sum of squares, ``k`` parameters, ``n`` bins);
* held-out data: the model is fitted on one half of the frames (or image blocks) and scored on
  the other half, and the other way round; ``heldout_chi2`` is the mean chi2 per bin.

The chosen model is the one with the lowest held-out chi2 (AICc breaks ties within 2 %).

Random error (``sigma`` against depth ``z``, metres):

* ``quadratic``: ``sigma = c z**2`` -- Intel's RMS = z**2 * subpixel / (f * B) for stereo;
  the subpixel value is ``c * f * B``;
* ``floor_quadratic``: ``sigma = sqrt(a**2 + (c z**2)**2)`` -- a depth-independent floor (e.g.
  surface roughness, registration resampling) plus stereo;
* ``poly2``: ``sigma = a + b z + c z**2``;
* ``linear``: ``sigma = a + b z`` -- time of flight (noise ~ distance).

Bias (mean residual against an independent reference, against ``z``):

* ``zero``, ``constant`` (``b``), ``linear`` (``b0 + b1 z``), ``disparity_offset``
  (``z / (1 + delta z / (f B)) - z``: a stereo camera whose disparity is off by ``delta`` px).

Spatial correlation of the noise (correlation ``rho`` at lag ``l`` px):

* ``white``: ``rho = 0`` for ``l >= 1``;
* ``gaussian``: ``rho = exp(-l**2 / (4 s**2))`` -- white noise blurred by a Gaussian of ``s``
  px (the simulator's ``correlation_px``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.optimize import least_squares


@dataclass(frozen=True)
class Candidate:
    """A model: name, parameter names, ``f(x, params) -> y``, starting values, lower bounds."""

    name: str
    params: tuple[str, ...]
    f: Callable[[np.ndarray, np.ndarray], np.ndarray]
    start: Callable[[np.ndarray, np.ndarray], np.ndarray]
    lower: tuple[float, ...] = ()


def _lsq_start(design):
    def start(x, y):
        A = design(x)
        return np.maximum(np.linalg.lstsq(A, y, rcond=None)[0], 0.0)
    return start


SIGMA_MODELS = (
    Candidate("quadratic", ("c",), lambda z, p: p[0] * z ** 2, _lsq_start(lambda z: z[:, None] ** 2), (0.0,)),
    Candidate("floor_quadratic", ("a", "c"), lambda z, p: np.sqrt(p[0] ** 2 + (p[1] * z ** 2) ** 2),
              lambda z, y: np.array([0.5 * np.min(y), np.median(y / z ** 2)]), (0.0, 0.0)),
    Candidate("poly2", ("a", "b", "c"), lambda z, p: p[0] + p[1] * z + p[2] * z ** 2,
              lambda z, y: np.linalg.lstsq(np.c_[np.ones_like(z), z, z ** 2], y, rcond=None)[0],
              (-np.inf, -np.inf, -np.inf)),
    Candidate("linear", ("a", "b"), lambda z, p: p[0] + p[1] * z,
              lambda z, y: np.linalg.lstsq(np.c_[np.ones_like(z), z], y, rcond=None)[0], (-np.inf, -np.inf)),
)


def bias_models(fB: float | None) -> tuple[Candidate, ...]:
    """Bias candidates; ``disparity_offset`` only for stereo (``fB`` = focal px x baseline m)."""
    out = [Candidate("zero", (), lambda z, p: np.zeros_like(z), lambda z, y: np.zeros(0)),
           Candidate("constant", ("b",), lambda z, p: np.full_like(z, p[0]), lambda z, y: np.array([np.mean(y)]),
                     (-np.inf,)),
           Candidate("linear", ("b0", "b1"), lambda z, p: p[0] + p[1] * z,
                     lambda z, y: np.linalg.lstsq(np.c_[np.ones_like(z), z], y, rcond=None)[0], (-np.inf, -np.inf))]
    if fB:
        out.append(Candidate("disparity_offset", ("delta_px",), lambda z, p: z / (1 + p[0] * z / fB) - z,
                             lambda z, y: np.array([0.0]), (-np.inf,)))
    return tuple(out)


CORRELATION_MODELS = (
    Candidate("white", (), lambda l, p: np.zeros_like(l), lambda l, y: np.zeros(0)),
    Candidate("gaussian", ("s_px",), lambda l, p: np.exp(-l ** 2 / (4 * max(p[0], 1e-6) ** 2)),
              lambda l, y: np.array([1.0]), (0.05,)),
)


@dataclass
class Fit:
    """One fitted candidate: parameters (with 1-sigma errors), chi2, AICc, held-out chi2 per bin."""

    model: str
    params: dict[str, float]
    errors: dict[str, float]
    chi2: float
    n: int
    aicc: float
    heldout_chi2: float = float("nan")

    def to_dict(self) -> dict:
        return {"model": self.model, "params": self.params, "errors": self.errors, "chi2": self.chi2, "n": self.n,
                "aicc": self.aicc, "heldout_chi2": self.heldout_chi2}


@dataclass
class Selection:
    """All fits of one quantity and the chosen one."""

    quantity: str
    fits: list[Fit]
    chosen: str
    notes: list[str] = field(default_factory=list)

    @property
    def best(self) -> Fit:
        return next(f for f in self.fits if f.model == self.chosen)

    def to_dict(self) -> dict:
        return {"quantity": self.quantity, "chosen": self.chosen, "fits": [f.to_dict() for f in self.fits],
                "notes": self.notes}


def _valid(x, y, se):
    x, y, se = (np.asarray(a, np.float64) for a in (x, y, se))
    ok = np.isfinite(x) & np.isfinite(y) & np.isfinite(se) & (se > 0)
    return x[ok], y[ok], se[ok]


def fit_candidate(c: Candidate, x, y, se) -> Fit:
    """Weighted least-squares fit of ``c`` to ``y(x) +- se``; parameter errors from the Jacobian."""
    x, y, se = _valid(x, y, se)
    n, k = len(x), len(c.params)
    if k == 0:
        chi2 = float(np.sum(((y - c.f(x, np.zeros(0))) / se) ** 2))
        return Fit(c.name, {}, {}, chi2, n, _aicc(chi2, k, n))
    if n < k:
        return Fit(c.name, {p: float("nan") for p in c.params}, {}, float("inf"), n, float("inf"))
    p0 = np.asarray(c.start(x, y), np.float64)
    lo = np.asarray(c.lower or (-np.inf,) * k, np.float64)
    p0 = np.where(np.isfinite(lo), np.maximum(p0, lo + 1e-12), p0)
    res = least_squares(lambda p: (c.f(x, p) - y) / se, p0, bounds=(lo, np.full(k, np.inf)), x_scale="jac")
    chi2 = float(np.sum(res.fun ** 2))
    try:
        cov = np.linalg.pinv(res.jac.T @ res.jac) * max(chi2 / max(n - k, 1), 1.0)
        err = np.sqrt(np.maximum(np.diag(cov), 0.0))
    except np.linalg.LinAlgError:
        err = np.full(k, np.nan)
    return Fit(c.name, dict(zip(c.params, map(float, res.x))), dict(zip(c.params, map(float, err))), chi2, n,
               _aicc(chi2, k, n))


def _aicc(chi2: float, k: int, n: int) -> float:
    return chi2 + 2 * k + (2 * k * (k + 1) / (n - k - 1) if n - k - 1 > 0 else float("inf") if k else 0.0)


def heldout_chi2(c: Candidate, train: tuple, test: tuple) -> float:
    """Mean chi2 per bin on ``test`` = (x, y, se) of ``c`` fitted on ``train``."""
    f = fit_candidate(c, *train)
    x, y, se = _valid(*test)
    if not f.params and c.params or not len(x):
        return float("nan")
    p = np.array([f.params[k] for k in c.params])
    return float(np.mean(((c.f(x, p) - y) / se) ** 2))


def select(quantity: str, candidates, data: tuple, halves: tuple[tuple, tuple] | None = None) -> Selection:
    """Fit every candidate to ``data`` = (x, y, se); with ``halves`` (two such triples from
    disjoint frames/blocks), score each on held-out data and choose by it, else by AICc."""
    fits = [fit_candidate(c, *data) for c in candidates]
    notes = []
    if halves is not None:
        for c, f in zip(candidates, fits):
            a, b = heldout_chi2(c, halves[0], halves[1]), heldout_chi2(c, halves[1], halves[0])
            f.heldout_chi2 = float(np.nanmean([a, b])) if np.isfinite([a, b]).any() else float("nan")
    scored = [f for f in fits if np.isfinite(f.heldout_chi2)]
    if scored:
        best = min(f.heldout_chi2 for f in scored)
        close = [f for f in scored if f.heldout_chi2 <= best * 1.02 + 1e-12]
        chosen = min(close, key=lambda f: f.aicc).model
    else:
        notes.append("no held-out split available: chosen by AICc alone")
        finite = [f for f in fits if np.isfinite(f.aicc)]
        chosen = min(finite, key=lambda f: f.aicc).model if finite else fits[0].model
    return Selection(quantity, fits, chosen, notes)
