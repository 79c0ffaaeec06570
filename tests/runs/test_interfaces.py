"""A whole run of a scene with several light field interfaces (``lft run``'s use case): verified against the ground
truth, with the first interface alone as its negative control; the rigs and models it cannot use yet refused in
one line (docs/interfaces.md)."""

from __future__ import annotations

import json

import imageio.v3 as iio
import pytest

from lftransfer.runs.pipeline import RunOptions, count_run_steps, run_scene
from lftransfer.runs.rigs import RigSpec
from lftransfer.scenes import SceneError, builtin_scene, load_scene, with_overrides
from lftransfer.scenes.resolution import quick_scene
from lftransfer.settings import Overrides
from tests.transfer.test_interfaces import _corner


@pytest.mark.slow
def test_01_a_run_through_two_interfaces_and_its_negative_control(variant, tmp_path):
    """The built-in corner at quarter resolution, a small view: the lamp behind "side" lights the block through it
    alone, so the run through "front" alone misses that light and is measurably worse."""
    scene = quick_scene(load_scene(builtin_scene("corner")))
    scene = with_overrides(scene, view={"resolution": [96, 72]})
    options = RunOptions(settings=Overrides(bounces=1, gt_spp=256), capture_spp=1, rig_model="oracle")
    steps = []
    report = run_scene(scene, tmp_path / "run", options, progress=lambda _msg, done: steps.append(done))
    assert steps[-1] == count_run_steps(scene, options)
    assert json.loads((tmp_path / "run" / "report.json").read_text()) == json.loads(json.dumps(report))
    panel = iio.imread(tmp_path / "run" / "interfaces.png")   # per interface: its LF camera's capture, its projector's
    w, h = scene.rig.projector                                  # final image (the LF camera's resized to its width)
    assert panel.shape[:2] == (2 * h, 2 * w)
    for row in (panel[:h], panel[h:]):
        assert row[h // 4:, :w].mean() > 5 and row[h // 4:, w:].mean() > 1      # below the labels: both lit
    faces = report["interfaces"]
    assert faces["names"] == ["front", "side"]
    assert all(len(energies) == 2 and energies[1] > 0 for energies in faces["real_energy"])
    control = report["negative_control"]
    assert control["rig_model"] == "through the first interface alone"
    assert control["measurably_worse"]
    assert control["cross_transfer_rel_error"] > 1.5 * report["cross_transfer_rel_error"]
    added = faces["added_light"]["added_radiance"]
    assert added["run"] > 10 * added["first_interface_only"]
    assert added["run"] == pytest.approx(added["ground_truth"], rel=0.25)
    # both sides' floors, every projector searched at once (sim.floor.JointProjectors)
    floor = report["fidelity_floor"]
    assert floor["real"]["floor"] <= floor["real"]["transfer"] and floor["synthetic"]["floor"] > 0
    assert report["transfer_over_floor"] >= 0.9


@pytest.mark.parametrize("options, what", [
    (RunOptions(rig_model="oracle", rig=RigSpec("replay", None)), "they run on the simulated rig in this process"),
    (RunOptions(rig_model="calibrated", rig=RigSpec("replay", None)), "they run on the simulated rig in this process"),
])
def test_02_what_several_interfaces_cannot_run_on_yet_is_said(variant, tmp_path, options, what):
    with pytest.raises(SceneError, match=what):
        run_scene(_corner(), tmp_path / "run", options)
    assert json.loads((tmp_path / "run" / "status.json").read_text())["state"] == "failed"


def test_03_the_use_cases_of_one_interface_refuse_several(variant, tmp_path):
    """A sequence, the live page, a benchmark or a study would run the first interface alone: they refuse such a
    scene in one line instead."""
    from lftransfer.runs.rigs import open_rig

    from lftransfer.sim.oracle import open_simulated_rig

    with pytest.raises(SceneError, match="lft run and lft calibrate take them"):
        open_rig(_corner(), RunOptions(rig_model="oracle"))
    with pytest.raises(SceneError, match="this command simulates one"):      # lft depth, the device twin, ...
        open_simulated_rig(_corner(), 0)


def test_04_a_reused_calibration_restores_every_interface_s_noise(variant):
    """The calibration cache stores the rigs' random streams after calibrating, so a run that reuses it draws the
    noise the calibrating run drew next: with several interfaces, every interface's. A capture after restoring
    repeats the one after saving, on each interface; without restoring it does not (the control)."""
    from lftransfer.runs.rigs import open_rig

    opened = open_rig(_corner(), RunOptions(rig_model="oracle"), interfaces=True)
    state = opened.noise_state()
    assert len(state["interfaces"]) == 2
    first = [r.capture_lf().codes for r in opened.rigs]
    again = [r.capture_lf().codes for r in opened.rigs]
    assert all((a != b).any() for a, b in zip(first, again))                 # the sensor noise moved on
    opened.restore_noise_state(state)
    repeated = [r.capture_lf().codes for r in opened.rigs]
    assert all((a == b).all() for a, b in zip(first, repeated))
