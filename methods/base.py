"""The one interface every depth-denoising method implements, and the method registry.

A method is a :class:`Denoiser` subclass with a ``name``, a ``version`` (bumped whenever its
output for the same input would change, so cached benchmark results are recomputed) and its
parameters. ``denoise(depth, color=None, camera=None)`` takes float32 metres with NaN holes and
returns the same.
"""
from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from capture.camera import Intrinsics
from methods.errors import MethodError, UnknownMethodError

_REGISTRY: dict[str, type["Denoiser"]] = {}


def register(cls: type["Denoiser"]) -> type["Denoiser"]:
    """Class decorator: make a method available by its ``name``."""
    if cls.name in _REGISTRY and _REGISTRY[cls.name] is not cls:
        raise MethodError(f"method name {cls.name!r} registered twice")
    _REGISTRY[cls.name] = cls
    return cls


def available() -> dict[str, type["Denoiser"]]:
    """Registered methods by name, in registration order."""
    import methods.registry  # noqa: F401  (imports every method module so each registers itself)

    return dict(_REGISTRY)


#: The seed report's abbreviations (Table I), accepted wherever a method name is.
ALIASES = {"bf": "bilateral", "jbf": "joint_bilateral", "rgf": "rolling_guidance"}


def get(name: str, **params: Any) -> "Denoiser":
    """An instance of method ``name`` (or its alias, e.g. ``"bf"``) with ``params`` overriding its defaults."""
    methods = available()
    resolved = name if name in methods else ALIASES.get(name, name)
    if resolved not in methods:
        aliases = ", ".join(f"{a}={n}" for a, n in ALIASES.items() if n in methods)
        raise UnknownMethodError(f"unknown method {name!r} (known: {', '.join(methods)}; aliases: {aliases})")
    return methods[resolved](**params)


def check_depth(depth: np.ndarray, *, name: str = "depth") -> np.ndarray:
    """The shared input check: ``(H, W)`` float32 metres, NaN holes, not all holes.

    Depth must be positive where it is not NaN: ``0`` and negative values, or infinities, are
    refused (a zero-for-hole map would silently pull every filter toward zero).
    """
    if not isinstance(depth, np.ndarray):
        raise MethodError(f"{name} must be a numpy array, got {type(depth).__name__}")
    if depth.ndim != 2:
        raise MethodError(f"{name} must have shape (H, W), got {depth.shape}")
    if depth.dtype != np.float32:
        raise MethodError(f"{name} must be float32 metres with NaN holes, got {depth.dtype}")
    finite = np.isfinite(depth)
    if not finite.any():
        raise MethodError(f"{name} has no valid pixel (all NaN)")
    if np.isinf(depth).any():
        raise MethodError(f"{name} has infinite values; mark missing depth with NaN")
    if (depth[finite] <= 0).any():
        raise MethodError(f"{name} has zero or negative values; mark missing depth with NaN, not 0")
    return depth


def check_color(color: np.ndarray | None, depth: np.ndarray) -> np.ndarray | None:
    """Colour guide: ``(H, W, 3)`` RGB or ``(H, W)``, the depth's size; uint8, uint16 or float32."""
    if color is None:
        return None
    if not isinstance(color, np.ndarray) or color.ndim not in (2, 3) or color.shape[:2] != depth.shape \
            or (color.ndim == 3 and color.shape[2] != 3):
        shape = getattr(color, "shape", None)
        raise MethodError(f"color must have shape {depth.shape} or {depth.shape + (3,)} like the depth, got {shape}")
    if color.dtype not in (np.uint8, np.uint16, np.float32):
        raise MethodError(f"color must be uint8, uint16 or float32, got {color.dtype}")
    if color.dtype == np.float32 and not np.isfinite(color).all():
        raise MethodError("color has NaN or infinite values")
    return color


def guide_planes(color: np.ndarray) -> np.ndarray:
    """A checked colour image as a float32 guide in its own units: ``(H, W)`` or planar ``(3, H, W)``."""
    guide = color.astype(np.float32)
    return guide if guide.ndim == 2 else np.ascontiguousarray(np.moveaxis(guide, 2, 0))


def _number(method: str, name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise MethodError(f"{method}: {name} must be a number, got {value!r}")
    return float(value)


def check_sigma(value: Any, name: str, *, method: str, unit: str, allow_inf: bool = False) -> float:
    """A Gaussian width: a finite number > 0 (``inf`` too where ``allow_inf``: the kernel is off)."""
    v = _number(method, name, value)
    if np.isnan(v) or v <= 0 or (np.isinf(v) and not allow_inf):
        raise MethodError(f"{method}: {name} must be a positive number of {unit}, got {value!r}")
    return v


def _integer_in(value: Any, low: int, high: int) -> bool:
    """True for an integral number (``3`` or ``3.0``, not ``True``) within ``[low, high]``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer, float, np.floating)):
        return False
    v = float(value)
    return bool(np.isfinite(v)) and v == int(v) and low <= int(v) <= high


def check_radius(value: Any, sigma_spatial: float, *, method: str) -> int:
    """Window radius in pixels: an integer >= 1; ``None`` derives ``max(1, ceil(2 * sigma_spatial))``."""
    if value is None:
        return max(1, int(np.ceil(2.0 * sigma_spatial - 1e-9)))
    if not _integer_in(value, 1, 100):
        raise MethodError(f"{method}: radius must be an integer number of pixels from 1 to 100 (or none), got {value!r}")
    return int(value)


def check_iterations(value: Any, *, method: str) -> int:
    """An iteration count: an integer >= 1."""
    if not _integer_in(value, 1, 1000):
        raise MethodError(f"{method}: iterations must be an integer from 1 to 1000, got {value!r}")
    return int(value)


def check_flag(value: Any, name: str, *, method: str) -> bool:
    """A yes/no option: a bool (``true``/``false`` on the command line)."""
    if not isinstance(value, (bool, np.bool_)):
        raise MethodError(f"{method}: {name} must be true or false, got {value!r}")
    return bool(value)


class Denoiser:
    """Base class of every method.

    Subclasses set ``name``, ``version``, ``defaults`` (parameter -> default, ``None`` meaning
    "derive the documented default") and implement :meth:`_denoise`.
    """

    name: ClassVar[str] = ""
    version: ClassVar[str] = "1"
    description: ClassVar[str] = ""
    defaults: ClassVar[dict[str, Any]] = {}
    #: one line per parameter: meaning and unit (shown by ``depthbench methods list``)
    param_help: ClassVar[dict[str, str]] = {}
    learned: ClassVar[bool] = False
    uses_color: ClassVar[bool] = False

    def __init__(self, **params: Any) -> None:
        unknown = sorted(set(params) - set(self.defaults))
        if unknown:
            raise MethodError(f"{self.name}: unknown parameter {unknown[0]!r} (known: {', '.join(self.defaults) or 'none'})")
        self.params = {**self.defaults, **params}
        self.check_params(self.params)

    def check_params(self, params: dict[str, Any]) -> None:
        """Raise :class:`MethodError` for impossible parameters (negative sigmas, ...)."""

    @property
    def key(self) -> str:
        """Identity for caching: name, version and parameters."""
        items = ",".join(f"{k}={v}" for k, v in sorted(self.params.items()))
        return f"{self.name}@{self.version}({items})"

    def denoise(self, depth: np.ndarray, color: np.ndarray | None = None,
                camera: Intrinsics | None = None) -> np.ndarray:
        depth = check_depth(depth)
        color = check_color(color, depth)
        out = self._denoise(depth, color, camera)
        return out.astype(np.float32, copy=False)

    def _denoise(self, depth: np.ndarray, color: np.ndarray | None, camera: Intrinsics | None) -> np.ndarray:
        raise NotImplementedError

    def __repr__(self) -> str:
        return self.key


@register
class Raw(Denoiser):
    """The identity: the LQ depth as the sensor gave it (every leaderboard's first column)."""

    name = "raw"
    description = "identity (the sensor's depth)"

    def _denoise(self, depth, color, camera):
        return depth.copy()
