"""The digital twin: a simulated rig with a hidden truth, operator errors, ground truth and every metric that
compares with truth (docs/architecture.md, "The simulator").

The core (optics, lightfield, render, rig, calibration, transfer) never imports this package; an import
contract in ``pyproject.toml`` checked by ``make test`` says so.
"""

from lftransfer.sim.rig import SimRig
from lftransfer.sim.truth import Perturbation, hidden_world, perturbed_rig, true_light_scene

__all__ = ["Perturbation", "SimRig", "hidden_world", "perturbed_rig", "true_light_scene"]
