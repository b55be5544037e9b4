"""Imports every method module so each registers itself with :func:`methods.base.register`.

Add a line here when a method module is added. Order is the order of ``depthbench methods list``.
"""
import methods.base  # noqa: F401  (raw)
import methods.gaussian  # noqa: F401
import methods.bilateral  # noqa: F401
import methods.joint_bilateral  # noqa: F401
import methods.rolling_guidance  # noqa: F401
