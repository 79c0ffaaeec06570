"""Calibration of several light field interfaces into one world frame (calibration/interfaces.py)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from lftransfer.calibration.interfaces import (FORMAT, InterfacesCalibration, count_steps, interface_scene,
                                               placed_calibration, read_calibration)
from lftransfer.calibration.pose import BOARD_CLEARANCE_M, CHART, board_pattern, sees_lit_side
from lftransfer.calibration.rig import Calibration, CalibrationFileError, calibrate_rig, count_calibration_steps, \
    load_calibration
from lftransfer.calibration.targets import target
from lftransfer.optics.geometry import rotation_matrix
from lftransfer.scenes import builtin_scene, load_scene, quick_scene
from lftransfer.scenes.interfaces import walls
from lftransfer.sim.calibration_errors import calibration_errors, interfaces_calibration_errors
from lftransfer.sim.oracle import open_simulated_interfaces
from lftransfer.sim.truth import true_interfaces

SIZE = ((CHART[0] + 2) * CHART[2], (CHART[1] + 2) * CHART[2])       # the pose boards


def _heights(planes: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ planes[:, :3].T + planes[:, 3]


def test_01_interface_scene_and_walls():
    """Each interface calibrates in its own frame: the view camera carried there exactly, the point lights with the
    first only; the other arrays' planes there measure the same heights as in the world."""
    scene = load_scene(builtin_scene("enclosure")).synthetic_part()
    first, side = interface_scene(scene, 0), interface_scene(scene, 1)
    assert first.view == scene.view and first.lights == scene.lights and first.interfaces == []
    assert side.lights == [] and side.interfaces == [] and side.rig == scene.rig
    to_world = scene.interfaces[1].to_world()
    back = to_world[:3, :3] @ np.asarray(side.view.origin) + to_world[:3, 3]
    np.testing.assert_allclose(back, scene.view.origin, atol=1e-12)
    # a point of the real space, in the side's frame: its heights above the front (z) and top (0.13 - y) arrays
    world = np.array([-0.02, -0.005, 0.08])
    local = np.linalg.inv(to_world)[:3, :3] @ (world - to_world[:3, 3])
    np.testing.assert_allclose(_heights(walls(scene.interfaces, 1), local[None])[0], [0.08, 0.135], atol=1e-12)
    assert walls([], 0).shape == (0, 4)
    assert count_steps(scene) == sum(count_calibration_steps(interface_scene(scene, i)) for i in range(3))
    fig4 = load_scene(builtin_scene("fig4"))
    assert count_steps(fig4) == count_calibration_steps(fig4) < count_steps(scene)


def test_02_screens_keep_clear_of_the_other_arrays():
    """A translucent screen stands on the view camera's line of sight unless that takes it through another
    interface's array: then it stays on its own array's axis, clear of every wall."""
    scene = load_scene(builtin_scene("enclosure")).synthetic_part()
    side = interface_scene(scene, 1)
    planes = walls(scene.interfaces, 1)
    assert not sees_lit_side(side.view, 0.07)

    def corners(b):
        return np.array([b.centre + sx * SIZE[0] / 2 * b.ex + sy * SIZE[1] / 2 * b.ey for sx in (-1, 1)
                         for sy in (-1, 1)])

    free = board_pattern(side.view, 0.07, translucent=True, extent=SIZE)
    assert _heights(planes, corners(free)).min() < 0              # the control: through the front array
    kept = board_pattern(side.view, 0.07, translucent=True, extent=SIZE, walls=planes)
    np.testing.assert_allclose(kept.centre[:2], 0.0, atol=1e-12)
    assert _heights(planes, corners(kept)).min() >= BOARD_CLEARANCE_M
    np.testing.assert_allclose(kept.normal, free.normal)
    # where the line of sight is clear, the walls change nothing
    front = interface_scene(scene, 0)
    b = board_pattern(front.view, 0.07, translucent=True, extent=SIZE)
    c = board_pattern(front.view, 0.07, translucent=True, extent=SIZE, walls=walls(scene.interfaces, 0))
    if _heights(walls(scene.interfaces, 0), corners(b)).min() >= BOARD_CLEARANCE_M:
        np.testing.assert_array_equal(b.centre, c.centre)


def _two(calibrated_rig):
    """An InterfacesCalibration of the quick corner scene built from the shared calibration of a Fig. 4 rig (the
    same hardware), placed where each interface stands; the second without the point light."""
    _scene, _rig, cal, _ = calibrated_rig
    corner = quick_scene(load_scene(builtin_scene("corner"))).synthetic_part()
    made = [placed_calibration(cal, corner, 0), placed_calibration(replace(cal, lights=[]), corner, 1)]
    return corner, InterfacesCalibration(names=("front", "side"), interfaces=made)


def test_03_file_round_trip_and_refusals(calibrated_rig, tmp_path):
    """The file holds each interface's calibration in its own frame; read back for the scene, each model stands
    where its [[interface]] table places it. A file of one interface for a scene of two, the reverse, and
    interfaces in another order are refused in one line naming the field."""
    corner, two = _two(calibrated_rig)
    path = two.write(tmp_path / "calibration.json")
    data = json.loads(path.read_text(encoding="utf-8"))
    assert data["format"] == FORMAT and [e["name"] for e in data["interfaces"]] == ["front", "side"]
    back = read_calibration(path, corner)
    assert isinstance(back, InterfacesCalibration) and back.names == ("front", "side")
    for want, got, face in zip(two.models, back.models, corner.interfaces):
        np.testing.assert_allclose(got.world_to_array(), want.world_to_array(), atol=1e-12)
        np.testing.assert_allclose(got.array.centres, want.array.centres, atol=1e-12)
        assert got.camera.exposure == pytest.approx(want.camera.exposure, rel=1e-12)
    np.testing.assert_allclose(back.models[1].placement, corner.interfaces[1].to_world(), atol=1e-12)
    assert back.models[0].placement == ()
    assert back.light_positions(corner) == two.light_positions(corner)
    one = calibrated_rig[2].write(tmp_path / "one.json")
    with pytest.raises(CalibrationFileError, match=r"one\.json: format: expected 'lftransfer-calibration-interfaces/1'"
                                                   r" .*front, side.*lft calibrate"):
        read_calibration(one, corner)
    with pytest.raises(CalibrationFileError, match=r"calibration\.json: interfaces: .*the scene has one"):
        read_calibration(path, calibrated_rig[0].synthetic_part())
    data["interfaces"].reverse()
    (tmp_path / "swapped.json").write_text(json.dumps(data), encoding="utf-8")
    with pytest.raises(CalibrationFileError, match=r"swapped\.json: interfaces: the file calibrates \['side', "
                                                   r"'front'\], but the scene's interfaces are \['front', 'side'\]"):
        read_calibration(tmp_path / "swapped.json", corner)
    data["interfaces"].reverse()
    data["interfaces"][1]["calibration"]["lens_array"]["rows"] = 3
    (tmp_path / "bad.json").write_text(json.dumps(data), encoding="utf-8")
    with pytest.raises(CalibrationFileError, match=r"bad\.json: interfaces\[1\]\.calibration: lens_array: a 3 x 12"):
        read_calibration(tmp_path / "bad.json", corner)
    with pytest.raises(TypeError, match="read_calibration"):
        load_calibration(path, corner)


def test_04_errors_in_the_world_and_between_arrays(calibrated_rig):
    """Against the truth itself every pose error is zero. Turning the second array in its plane by 0.1 degrees
    is a 0.1 degree error of its own and against the first; tilting the first by 0.1 degrees is the first's own
    error, leaves the second's own pose exact, and moves the second's lenslets in the first's frame by about their
    distance times 0.1 degrees (the negative control of the relative error)."""
    corner, two = _two(calibrated_rig)
    truths = true_interfaces(corner, 4)

    def as_calibrated(models):
        return InterfacesCalibration(names=two.names, interfaces=[
            Calibration(model=m, lattice=None, distortion=None, projector_fit=None, radiometry=c.radiometry,
                        pose=c.pose) for m, c in zip(models, two.interfaces)])

    exact = interfaces_calibration_errors(as_calibrated(truths), truths).to_json()["interfaces"]
    for name in ("front", "side"):
        assert exact[name]["pose_position_max_mm"] < 1e-9 and exact[name]["pose_rotation_deg"] < 1e-5
    assert exact["side"]["relative_position_max_mm"] < 1e-9 and exact["side"]["relative_rotation_deg"] < 1e-5
    turned = replace(truths[1], array=replace(truths[1].array, rotation=truths[1].array.rotation + np.radians(0.1)))
    e = interfaces_calibration_errors(as_calibrated([truths[0], turned]), truths).to_json()["interfaces"]
    assert e["side"]["pose_rotation_deg"] == pytest.approx(0.1, rel=1e-6)
    assert e["side"]["relative_rotation_deg"] == pytest.approx(0.1, rel=1e-6)
    assert e["front"]["pose_rotation_deg"] < 1e-5
    tilted = replace(truths[0], tilt=(truths[0].tilt[0] + np.radians(0.1), truths[0].tilt[1]))
    e = interfaces_calibration_errors(as_calibrated([tilted, truths[1]]), truths).to_json()["interfaces"]
    assert e["front"]["pose_rotation_deg"] == pytest.approx(0.1, rel=1e-3)
    assert e["side"]["pose_rotation_deg"] < 1e-5 and e["side"]["pose_position_max_mm"] < 1e-9
    assert e["side"]["relative_rotation_deg"] == pytest.approx(0.1, rel=1e-3)
    reach = np.linalg.norm(np.linalg.inv(truths[1].world_to_array())[:3, 3])            # the side's centre, metres
    assert 0.3 * reach * np.radians(0.1) * 1000 < e["side"]["relative_position_rms_mm"] \
        < 2.0 * reach * np.radians(0.1) * 1000


@pytest.mark.slow
def test_05_the_side_interface_from_its_images():
    """The corner's second interface, turned 90 degrees in the world, calibrated from its own images in its own
    frame: lenslet centres and projector mapping within the targets, and the placed model takes world points into
    its array's frame as the true one does. Its pose, at this resolution (a 256 x 192 view camera that sees its
    boards through translucent screens), is 0.09 mm RMS, 0.14 mm at the worst lenslet and 0.045 degree on this
    hidden truth (seed 2): bounds 0.3 mm and 0.15 degree. It was 0.93 mm and 0.36 degree while the screens' charts
    were measured by their corners alone, before they were aligned as a whole (pose.aligned_corners)."""
    scene = quick_scene(load_scene(builtin_scene("corner")))
    rigs, oracle = open_simulated_interfaces(scene, 2, capture_spp=4)
    ps = scene.synthetic_part()
    cal = placed_calibration(calibrate_rig(rigs[1], interface_scene(ps, 1), walls=walls(ps.interfaces, 1)), ps, 1)
    e = calibration_errors(cal, oracle.models[1]).to_json()
    for key in ("projector_mapping_rms_px", "lenslet_centre_rms_px"):
        assert target(key).met(e[key]), (key, e[key])
    assert e["pose_position_max_mm"] <= 0.3 and e["pose_rotation_deg"] <= 0.15, e
    assert e["lenslet_assignment_agreement"] > 0.999 and e["ray_direction_rms_deg"] < 0.5
    world = np.array([[-0.05, 0.02, 0.12, 1.0]])
    got = (cal.model.world_to_array() @ world.T)[:3, 0]
    want = (oracle.models[1].world_to_array() @ world.T)[:3, 0]
    assert np.linalg.norm(got - want) < 0.003          # a few tenths of a degree at 0.2 m from the array, metres
    np.testing.assert_allclose(cal.model.placement, oracle.models[1].placement)
    rotation = np.asarray(cal.model.placement)[:3, :3]
    np.testing.assert_allclose(rotation, rotation_matrix(scene.interfaces[1].rotate_deg), atol=1e-12)


@pytest.mark.slow
def test_06_the_exposure_board_seen_from_an_array_that_faces_the_view_camera():
    """The enclosure's view camera faces its side array, so the exposure board turns about 70 degrees from that
    array's axis, and the lenslets' steepest rays meet it from behind, where it is unlit: those rays are left out,
    and the LF camera's exposure, measured with the true model otherwise, comes out within its 1 % target (it came
    out 7 % low with them). On Fig. 4's rig, with its board turned 41 degrees, none is left out."""
    from lftransfer.calibration.rig import calibrate_exposure
    from lftransfer.sim.interfaces import SimInterfaces
    from lftransfer.sim.truth import hidden_world

    scene = quick_scene(load_scene(builtin_scene("enclosure")))
    world, _ = hidden_world(scene, 0)
    rig = SimInterfaces(world, truths=true_interfaces(scene, 0), capture_spp=4, operator_seed=0).rigs[1]
    truth = replace(rig.truth, placement=())
    exposure, diag = calibrate_exposure(rig, truth, interface_scene(scene.synthetic_part(), 1))
    assert diag["rays_left_out"] > 50 and diag["rays"] > 1000
    assert target("exposure_rel_error").met(exposure / truth.camera.exposure - 1)
    fig4 = quick_scene(load_scene(builtin_scene("fig4")))
    from lftransfer.sim.rig import SimRig

    one = SimRig(fig4, capture_spp=4)
    _, diag = calibrate_exposure(one, one.truth, fig4.synthetic_part())
    assert diag["rays_left_out"] == 0
