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
    """A benchmark or a study would run the first interface alone: they refuse such a scene in
    one line instead."""
    from lftransfer.runs.rigs import open_rig

    from lftransfer.sim.oracle import open_simulated_rig

    with pytest.raises(SceneError, match="lft run, lft calibrate, lft render and lft live take them"):
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


def test_05_live_and_converged_sequences_through_two_interfaces(variant, tmp_path):
    """``lft render`` through both arrays of the corner: a live sequence keeps each projector's next light field
    (an interrupted one resumes from them), its panels show each interface's LF camera and projector, and its
    frames carry the exchange (the composite brightens after frame 0); a converged frame is the bounce loop through
    both, verified against the ground truth; the decoupled loop runs its simulator in this process."""
    import numpy as np

    from lftransfer.imageio_utils import read_exr
    from lftransfer.runs.sequence import SequenceOptions, render_sequence

    scene = _corner(lamp=True)
    out = tmp_path / "live"
    options = RunOptions(rig_model="oracle", settings=Overrides(gt_spp=16))

    def stop_after_two(_record, done, _total):
        if done == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        render_sequence(scene, out, options, SequenceOptions(frames=3), progress=stop_after_two)
    with np.load(out / "state" / "projected_lf.npz") as z:
        assert sorted(z.files) == ["data", "data_1"] and z["data"].any() and z["data_1"].any()
    report = render_sequence(scene, out, options, SequenceOptions(frames=3, resume=True))
    assert [f["index"] for f in report["frames"]] == [0, 1, 2]
    panel = iio.imread(out / "frames" / "panel_0002.png")
    bottom = iio.imread(out / "frames" / "0002.png")
    tile_height = panel.shape[1] / 3 * bottom.shape[0] / bottom.shape[1]       # three tiles a row, the view's shape
    assert round(panel.shape[0] / tile_height) == 3     # "front"'s devices, "side"'s, the views (one interface: 2)
    first, last = (read_exr(out / "frames" / f"{i:04d}.exr") for i in (0, 2))
    assert last.sum() > first.sum()                                # the bounces accumulate over the frames
    converged = render_sequence(scene, tmp_path / "converged", options,
                                SequenceOptions(mode="converged", frames=1, verify_every=1))
    metrics = converged["frames"][0]["metrics"]
    assert metrics["psnr_objects_db"] > 20
    decoupled = render_sequence(scene, tmp_path / "decoupled", options, SequenceOptions(loop="decoupled", frames=2))
    assert decoupled["loop"] == "decoupled" and len(decoupled["frames"]) == 2


def test_06_one_rig_file_per_interface(variant, tmp_path):
    """``--rig hardware:A.toml,B.toml`` names one rig file per interface, in the scene's order: it is parsed and
    printed back whole, and a scene of one interface refuses two rig files in one line before any device opens."""
    from lftransfer.runs.rigs import open_rig
    from tests.small import write_tiny_scene

    files = [tmp_path / "front.toml", tmp_path / "side.toml"]
    for f in files:
        f.write_text("")
    spec = RigSpec.parse(f"hardware:{files[0]},{files[1]}")
    assert spec.paths == tuple(files) and spec.path == files[0] and str(spec) == f"hardware:{files[0]},{files[1]}"
    assert RigSpec.parse(f"hardware:{files[0]}").paths == (files[0],)
    with pytest.raises(ValueError, match="does not exist"):
        RigSpec.parse(f"hardware:{files[0]},{tmp_path / 'missing.toml'}")
    with pytest.raises(SceneError, match="2 rig files for a scene of one light field interface"):
        open_rig(load_scene(write_tiny_scene(tmp_path / "tiny.toml")), RunOptions(rig=spec))
