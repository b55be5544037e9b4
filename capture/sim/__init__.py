"""The simulator: rigs of RGB-D sensors filming a moving scene, with ground truth.

``simulate(out, *, rig, scene, seconds, seed, effects, undeclared, force, ...)`` writes a
session folder (``capture.session`` format) plus ``truth/`` (``data_manifests/truth.md``);
read the truth back with :func:`capture.truth.read_truth`.

Modules: ``scene`` (meshes and motion), ``texture`` (procedural colour fixed to surfaces),
``rigs`` (sensors and poses), ``noise`` (stereo and ToF physics), ``clocks`` (per-sensor
clocks, drops), ``render`` (batched Open3D ray casting), ``sensors`` (hits to frames),
``output`` (session.json and truth/), ``simulate`` (the library function).
"""
from capture.sim.effects import EFFECTS, parse_effects
from capture.sim.errors import SimulationError
from capture.sim.rigs import RIGS
from capture.sim.scene import SCENES
from capture.sim.simulate import SimulationResult, simulate

__all__ = ["EFFECTS", "RIGS", "SCENES", "SimulationError", "SimulationResult", "parse_effects", "simulate"]
