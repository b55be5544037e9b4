"""The method registry: every built-in method by name, the seed report's aliases, and lookup.

Built-in methods are listed here explicitly (:data:`BUILTIN`, in the order of ``depthbench methods
list``); method modules import only :mod:`methods.base`, so nothing imports back into this module
(no import cycle). Add a method by importing its class here and appending it to ``BUILTIN``.
:func:`register` adds a method at run time (tests, plugins).
"""
from __future__ import annotations

from typing import Any

from methods.base import Denoiser
from methods.bilateral import BilateralFilter
from methods.ddd.method import DDD
from methods.ddrnet.method import DDRNetDenoise, DDRNetRefine
from methods.errors import MethodError, UnknownMethodError
from methods.gaussian import GaussianFilter
from methods.joint_bilateral import JointBilateralFilter
from methods.raw import Raw
from methods.rolling_guidance import RollingGuidanceFilter
from methods.ssdd.denoise import SSDDLSTMDenoiser, SSDDUNetDenoiser

#: Built-in methods, in listing order.
BUILTIN: tuple[type[Denoiser], ...] = (Raw, GaussianFilter, BilateralFilter, JointBilateralFilter,
                                       RollingGuidanceFilter, DDRNetDenoise, DDD, SSDDUNetDenoiser, SSDDLSTMDenoiser,
                                       DDRNetRefine)

#: The seed report's abbreviations (Table I), accepted wherever a method name is.
ALIASES = {"bf": "bilateral", "jbf": "joint_bilateral", "rgf": "rolling_guidance"}

_EXTRA: dict[str, type[Denoiser]] = {}


def register(cls: type[Denoiser]) -> type[Denoiser]:
    """Class decorator: make a method that is not built in available by its ``name`` (tests, plugins)."""
    known = {c.name: c for c in BUILTIN} | _EXTRA
    if cls.name in known and known[cls.name] is not cls:
        raise MethodError(f"method name {cls.name!r} registered twice")
    _EXTRA[cls.name] = cls
    return cls


def unregister(name: str) -> None:
    """Remove a method added by :func:`register` (built-in methods stay)."""
    _EXTRA.pop(name, None)


def available() -> dict[str, type[Denoiser]]:
    """Registered methods by name: the built-in ones in listing order, then those added by :func:`register`."""
    return {**{c.name: c for c in BUILTIN}, **_EXTRA}


def aliases_of(name: str) -> list[str]:
    """The aliases of method ``name`` (e.g. ``["bf"]`` for ``"bilateral"``)."""
    return [a for a, n in ALIASES.items() if n == name]


def resolve_name(name: str) -> str:
    """A method name or alias -> the registered name; :class:`UnknownMethodError` listing the known ones."""
    methods = available()
    resolved = name if name in methods else ALIASES.get(name, name)
    if resolved not in methods:
        aliases = ", ".join(f"{a}={n}" for a, n in ALIASES.items() if n in methods)
        raise UnknownMethodError(f"unknown method {name!r} (known: {', '.join(methods)}; aliases: {aliases})")
    return resolved


def get(name: str, **params: Any) -> Denoiser:
    """An instance of method ``name`` (or its alias, e.g. ``"bf"``) with ``params`` overriding its defaults."""
    return available()[resolve_name(name)](**params)
