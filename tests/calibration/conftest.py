"""The calibrated rig the calibration tests share (a whole calibration takes some 30 s on 2 cores: made once)."""

from __future__ import annotations

import pytest

from lftransfer.calibration.rig import calibrate_rig
from lftransfer.scenes import builtin_scene, load_scene, quick_scene
from lftransfer.sim.rig import SimRig
from lftransfer.sim.truth import perturbed_rig, true_light_scene


@pytest.fixture(scope="session")
def calibrated_rig(variant):
    """(scene, rig, calibration, progress messages): a rig with hidden truth (seed 3) at quarter resolution,
    calibrated from its images alone; the simulated operator misplaces every board by a hidden hand error."""
    scene = quick_scene(load_scene(builtin_scene("fig4")))
    rig = SimRig(true_light_scene(scene, 3), truth=perturbed_rig(scene.rig, 3), operator_seed=3)
    messages = []
    cal = calibrate_rig(rig, scene.synthetic_part(), progress=messages.append)
    return scene, rig, cal, messages
