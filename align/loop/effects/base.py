"""The interface of a feature effect (see :mod:`align.loop.effects`): every hook neutral by default."""
from __future__ import annotations

import numpy as np

from capture.camera import Intrinsics


class Effect:
    """One effect model: ``name``, ``params`` (names), ``units``, ``steps`` (finite differences),
    ``requires`` (an effect that must be in the model first), ``declared_as`` (the session
    ``effects`` keys that declare it), ``signature`` (the residual covariate it shows against),
    ``what`` (one line for reports), ``model_error`` (per parameter: the error its estimate shows on
    rendered sessions beyond its fitted deviation, measured against the simulator's truth and added
    in quadrature to the stated deviation; 0 where none was measured), ``bounds`` (per parameter, the
    ``(low, high)`` range a real device can show: the non-linear refit stays inside it and an effect
    whose refitted parameter reaches an end is rejected; empty = unbounded)."""

    name: str = ""
    params: tuple[str, ...] = ()
    units: tuple[str, ...] = ()
    steps: tuple[float, ...] = ()
    requires: str | None = None
    declared_as: tuple[str, ...] = ()
    signature: str = ""
    what: str = ""
    model_error: tuple[float, ...] = ()
    bounds: tuple[tuple[float, float], ...] = ()

    def time_offset_us(self, data, v: np.ndarray):
        return 0.0

    def sample_offset_us(self, data, stamps: np.ndarray, v: np.ndarray) -> np.ndarray:
        return stamps

    def lq_camera(self, K: Intrinsics, v: np.ndarray) -> Intrinsics:
        return K

    def correct_points(self, data, X: np.ndarray, v: np.ndarray) -> np.ndarray:
        return X

    def model_errors(self, data) -> tuple[float, ...]:
        """Each parameter's model error for these features (default: the constant ``model_error``)."""
        return tuple(self.model_error) or (0.0,) * len(self.params)

    def ranges(self) -> list[tuple[float, float]]:
        """Each parameter's ``(low, high)`` physical range (default unbounded)."""
        return list(self.bounds) or [(-np.inf, np.inf)] * len(self.params)

    def declared_values(self, declared: dict) -> np.ndarray | None:
        """The parameter values a session's declared ``effects`` give this effect (None: not declared)."""
        return None

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name})"
