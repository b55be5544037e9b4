"""The simulator: rigs of RGB-D sensors filming a moving scene, with ground truth.

``simulate(out, *, rig, scene, seconds, seed, effects, undeclared, force, ...)`` writes a
session folder (``capture.session`` format) plus ``truth/`` (``data_manifests/truth.md``);
read the truth back with :func:`capture.truth.read_truth`.

Modules: ``scene`` (meshes and motion), ``texture`` (procedural colour fixed to surfaces),
``rigs`` (sensors and poses), ``noise`` (stereo and ToF physics), ``clocks`` (per-sensor
clocks, drops), ``render`` (batched Open3D ray casting), ``sensors`` (hits to frames),
``output`` (session.json and truth/), ``simulator`` (the library function :func:`simulate`; the module is
not named ``simulate``: importing a submodule binds its name on the package, which would hide the function).
"""
from capture.sim.effects import EFFECTS, parse_effects
from capture.sim.errors import SimulationError
from capture.sim.rigs import RIGS
from capture.sim.scene import SCENES

__all__ = ["EFFECTS", "RIGS", "SCENES", "SimulationError", "SimulationResult", "parse_effects", "simulate"]


def __getattr__(name: str):
    # ``simulate`` pulls in Open3D (about a second to import): load it only when used, so that
    # building the command-line parser (which needs RIGS, SCENES, EFFECTS) stays fast.
    if name in ("simulate", "SimulationResult"):
        import importlib

        module = importlib.import_module("capture.sim.simulator")
        globals().update(simulate=module.simulate, SimulationResult=module.SimulationResult)
        return globals()[name]
    raise AttributeError(f"module 'capture.sim' has no attribute {name!r}")
