"""Every calibration step through the simulated rig, against its hidden truth; the calibration file."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lftransfer.calibration.targets import target
from lftransfer.calibration.rig import CalibrationFileError, count_calibration_steps, load_calibration
from lftransfer.scenes import quick_scene
from lftransfer.calibration.light import LIGHT_BOARDS
from lftransfer.calibration.pose import POSE_DEPTHS, POSE_ROUNDS
from lftransfer.rig.requests import RealScene
from lftransfer.sim.rig import SimRig
from lftransfer.sim.truth import true_light_scene
from lftransfer.scenes import builtin_scene, load_scene
from lftransfer.sim.calibration_errors import calibration_errors


@pytest.fixture(scope="module")
def calibrated(calibrated_rig):
    """The shared calibrated rig (tests/calibration/conftest.py): hidden truth seed 3, a hidden hand error on every
    board."""
    return calibrated_rig


def test_01_recovers_the_hidden_rig(calibrated):
    """The issue's targets for lenslet centres (<= 0.1 px), projector mapping (<= 0.5 px) and responses (within
    1 % of full scale). The pose rests on the view camera, here 256 x 192 pixels (the printed chessboard's plane
    is measured to about half a millimetre), and on boards held by hand a few millimetres and about a degree off
    where they were asked for: at a quarter of the paper's resolution, three rounds reach 0.34 mm and 0.20 degree
    (bounds 0.7 mm, 0.35 degree), where at full resolution `lft calibrate seeds` measures the issue's targets of
    1 mm and 0.2 degree (docs/calibration.md). The exposure, averaged over a disc wider than a lenslet in both
    cameras, is 0.05 % off (bound 0.5 %). The point light, 3.1 mm from the scene file's position, is measured to
    0.67 mm (bound 1 mm; the chessboards' pose error at 256 x 192 view pixels, docs/calibration.md)."""
    scene, rig, cal, messages = calibrated
    e = calibration_errors(cal, rig.truth, true_lights=[lt.position for lt in true_light_scene(scene, 3).lights]).to_json()
    assert e["lenslets_found"] == 120
    for key in ("lenslet_centre_rms_px", "projector_mapping_rms_px", "camera_response_error",
                "projector_response_error", "light_position_error_mm"):     # met at this resolution too
        assert target(key).met(e[key]), key
    assert e["pose_position_rms_mm"] <= 0.7 and e["pose_rotation_deg"] <= 0.35
    assert abs(e["pitch_rel_error"]) < 0.005
    assert isinstance(rig._setup, RealScene)             # calibration leaves the rig in the real scene
    # brightness, exposure, pose and point light boards
    assert len(rig.boards_held) == 2 + POSE_ROUNDS * len(POSE_DEPTHS) + LIGHT_BOARDS
    assert cal.lights[0].residual_rms < 0.005
    assert e["ray_direction_rms_deg"] < 0.5 and e["lenslet_assignment_agreement"] > 0.999
    assert abs(e["exposure_rel_error"]) < 0.005 and e["projector_mixing_rel_error"] < 0.01
    assert len(messages) == count_calibration_steps(scene)


def test_02_file_round_trip(calibrated, tmp_path):
    """Written and read back, the calibration gives every camera and projector pixel the same ray."""
    scene, _, cal, _ = calibrated
    path = cal.write(tmp_path / "calibration.json")
    data = json.loads(path.read_text())
    lens = data["lf_camera"]["lenslets"][0]
    assert np.array(lens["camera_matrix"]).shape == (3, 3) and len(lens["dist_coeffs"]) == 5
    loaded = load_calibration(path, scene)
    back = loaded.model
    for a, b in ((cal.model.camera, back.camera), (cal.model.projector, back.projector)):
        px = np.stack(np.meshgrid(np.arange(0, a.device.width, 7), np.arange(0, a.device.height, 7)), -1)
        px = px.reshape(-1, 2).astype(float)
        ka, da = a.device.pixel_to_ray(cal.model.array, px)
        kb, db = b.device.pixel_to_ray(back.array, px)
        assert np.array_equal(ka, kb)
        np.testing.assert_allclose(da[ka >= 0], db[kb >= 0], atol=1e-12)
    assert back.tilt == pytest.approx(cal.model.tilt)
    assert back.camera.exposure == pytest.approx(cal.model.camera.exposure)
    assert back.projector.max_radiance == pytest.approx(cal.model.projector.max_radiance)
    np.testing.assert_allclose(back.projector.cross_talk, cal.model.projector.cross_talk)
    np.testing.assert_array_equal(loaded.lights[0].position, cal.lights[0].position)
    assert loaded.light_positions(scene) == [tuple(cal.lights[0].position)] != [tuple(scene.lights[0].position)]


def test_03_bad_files_are_named(calibrated, tmp_path):
    scene, _, cal, _ = calibrated
    missing = tmp_path / "missing.json"
    with pytest.raises(CalibrationFileError, match="missing.json"):
        load_calibration(missing, scene)
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({"format": "something else"}))
    with pytest.raises(CalibrationFileError, match="wrong.json.*format"):
        load_calibration(wrong, scene)
    other = tmp_path / "other.json"
    data = cal.to_json()
    data["lens_array"]["rows"] = 4
    other.write_text(json.dumps(data))
    with pytest.raises(CalibrationFileError, match="other.json.*lens_array"):
        load_calibration(other, scene)
    broken = tmp_path / "broken.json"
    del data["radiometry"]
    data["lens_array"]["rows"] = 10
    broken.write_text(json.dumps(data))
    with pytest.raises(CalibrationFileError, match="broken.json.*radiometry"):
        load_calibration(broken, scene)


def test_04_the_exposure_step_does_not_read_a_clipped_camera(variant, monkeypatch):
    """Fig. 5's rig (exposure 1.0, a projector of 40 W m^-2 sr^-1) makes the LF camera clip on a board the projector
    lights at 0.9 of its range: that reading put the exposure 78 % low at the paper's resolution. The step lowers
    the projector by quarters until no ray of the disc clips, and the exposure comes out within 0.1 % (measured
    0.09 % at level 0.056; target 1 %), as on Fig. 4's rig (level 0.9). Negative control: held at the first level,
    the step refuses rather than reading clipped codes."""
    import lftransfer.calibration.rig as calibration_rig
    from lftransfer.sim.truth import hidden_world

    for name, level in (("fig5", 0.9 / 16), ("fig4", 0.9)):
        scene = quick_scene(load_scene(builtin_scene(name)))
        world, truth = hidden_world(scene, 0)
        sim = SimRig(world, truth=truth, operator_seed=0)
        exposure, diag = calibration_rig.calibrate_exposure(sim, truth, scene.synthetic_part())
        assert abs(exposure / truth.camera.exposure - 1) < 0.002 and diag["projector_level"] == pytest.approx(level)
    monkeypatch.setattr(calibration_rig, "EXPOSURE_TRIES", 1)
    scene = quick_scene(load_scene(builtin_scene("fig5")))
    world, truth = hidden_world(scene, 0)
    with pytest.raises(ValueError, match="the LF camera clips on the lit board even with the projector at 0.9"):
        calibration_rig.calibrate_exposure(SimRig(world, truth=truth, operator_seed=0), truth, scene.synthetic_part())
