"""Imports every method module so each registers itself with :func:`methods.base.register`.

Add a line here when a method module is added.
"""
import methods.base  # noqa: F401  (raw)
