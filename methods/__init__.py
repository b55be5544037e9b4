"""Methods: one module per depth-denoising method behind the :class:`Denoiser` interface."""
from methods.base import Denoiser, available, get, register
from methods.errors import MethodError, UnknownMethodError

__all__ = ["Denoiser", "MethodError", "UnknownMethodError", "available", "get", "register"]
