"""Opt-in ``torch.compile`` of inference networks: ``DEPTHBENCH_COMPILE=1`` in the environment.

Inductor fuses a network's elementwise work (activations, concatenations, resizes) around its convolutions. On two
quiet CPU cores SSDD's level 1 at the default width (16, 4 levels, 640x480) ran 1.3-1.4x faster compiled, and
``ssdd_unet`` took 90 instead of 129 ms per frame; outputs equal the eager network's to float rounding (5e-7 m).
The price is the compilation: about 43 s (24 CPU-s) in a fresh process with an empty cache, 3-9 s with inductor's
on-disk cache warm, in every process and again for each new frame size (issue 10 worklog, session 11). That is why
it is off by default (the demo, the tests and a ``bench run`` over a few frames would pay more than they gain).

A compile error falls back to the eager network (``torch._dynamo`` error suppression, with its log line). Compiled
networks are not run from several threads at once (compilation is not thread-safe): callers turn inference lanes
(:mod:`methods.nn.lanes`) off when they compile.
"""
from __future__ import annotations

import os

ENV = "DEPTHBENCH_COMPILE"


def enabled() -> bool:
    """True when the environment variable :data:`ENV` is ``1``, ``true``, ``yes`` or ``on``."""
    return os.environ.get(ENV, "").strip().lower() in ("1", "true", "yes", "on")


def for_inference(net, *, device: str = "cpu"):
    """``torch.compile(net)`` when :func:`enabled` and ``device`` is the CPU, else ``net`` itself. The compiled
    module forwards attribute access (``cfg``, submodules) to ``net``."""
    if not enabled() or device != "cpu":
        return net
    import torch
    import torch._dynamo

    torch._dynamo.config.suppress_errors = True   # a graph inductor cannot compile runs eagerly instead
    return torch.compile(net)
