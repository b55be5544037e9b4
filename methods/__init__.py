"""Methods: one module per depth-denoising method behind the :class:`Denoiser` interface.

:mod:`methods.base` is the interface, :mod:`methods.registry` the list of methods and their
aliases, :mod:`methods.run` the one way to run a method over an aligned dataset.
"""
from methods.base import Denoiser, FrameInput, MethodNeeds
from methods.errors import MethodError, UnknownMethodError
from methods.registry import ALIASES, available, get, register

__all__ = ["ALIASES", "Denoiser", "FrameInput", "MethodError", "MethodNeeds", "UnknownMethodError", "available",
           "get", "register"]
