"""The calibration cache (lftransfer.runs.calibration_cache): keyed by what a simulated rig's calibration depends on,
checked on read, reused by a run with the same report as the run that calibrated, refused with one line when
corrupt, and bypassed by --recalibrate."""

from __future__ import annotations

import json

from lftransfer.runs import calibration_cache as cc
from lftransfer.runs.pipeline import RunOptions, count_run_steps, run_scene
from lftransfer.runs.rigs import calibration_key, will_calibrate
from lftransfer.scenes import builtin_scene, load_scene, with_overrides
from lftransfer.settings import Overrides
from lftransfer.sim.gt_cache import CacheProblem
from tests.small import write_tiny_scene


def _entry(tmp_path, inputs="a" * 64, state=None):
    run = tmp_path / "run"
    run.mkdir(exist_ok=True)
    for name, text in zip(cc.FILES, ('{"format": "x"}', '{"pose_rotation_deg": 0.01}', "<html></html>")):
        (run / name).write_text(text)
    return cc.write_entry(inputs, run, state or {"sensor": {"s": 1}, "boards": 3})


def test_01_an_entry_reads_back_and_every_bad_entry_is_named():
    """Written and read back: the files and the rig's state; a changed file, an entry of other inputs, a missing
    entry file and a missing checksum each give a CacheProblem whose line names the entry and what is done."""
    inputs = "b" * 64
    assert cc.read_entry(inputs) is None
    folder = _entry(cc.cache_dir().parent, inputs)
    entry = cc.read_entry(inputs)
    assert isinstance(entry, cc.CachedCalibration) and entry.folder == folder
    assert entry.rig_state == {"sensor": {"s": 1}, "boards": 3}
    assert entry.calibration_file.read_text() == '{"format": "x"}'

    (folder / "calibration_errors.json").write_text('{"pose_rotation_deg": 9}')          # changed after writing
    problem = cc.read_entry(inputs)
    assert isinstance(problem, CacheProblem)
    assert "calibration_errors.json" in problem.reason and "checksum" in problem.reason
    assert problem.message().startswith(f"calibration cache entry {folder}")
    assert "calibrating again" in problem.message()

    _entry(cc.cache_dir().parent, inputs)
    meta = json.loads((folder / "entry.json").read_text())
    (folder / "entry.json").write_text(json.dumps({**meta, "inputs_sha256": "c" * 64}))
    assert "other inputs" in cc.read_entry(inputs).reason
    (folder / "entry.json").unlink()
    assert "no entry.json" in cc.read_entry(inputs).reason
    _entry(cc.cache_dir().parent, inputs)
    (folder / "rig_state.json").unlink()
    assert "lacks rig_state.json" in cc.read_entry(inputs).reason


def test_02_the_key_changes_with_what_a_calibration_depends_on_only():
    """The truth seed, the capture rays, the devices and the real world change the key; the synthetic objects and
    the render settings, which the calibration never sees, do not."""
    scene = load_scene(builtin_scene("fig4"))
    key = cc.inputs_sha256(scene, 0, 4)
    assert key == cc.inputs_sha256(load_scene(builtin_scene("fig4")), 0, 4)
    assert key != cc.inputs_sha256(scene, 1, 4) and key != cc.inputs_sha256(scene, None, 4)
    assert key != cc.inputs_sha256(scene, 0, 2)
    assert key != cc.inputs_sha256(with_overrides(scene, rig={"lf_camera": [1024, 768]}), 0, 4)
    assert key != cc.inputs_sha256(with_overrides(scene, view={"fov_deg": scene.view.fov_deg + 1}), 0, 4)
    real = scene.real[0].model_dump(mode="json")
    moved = with_overrides(scene, real=[{**real, "translate": [0.01, 0.0, 0.07]}, *scene.real[1:]])
    assert key != cc.inputs_sha256(moved, 0, 4)
    cube = scene.synthetic[0].model_dump(mode="json")
    assert key == cc.inputs_sha256(with_overrides(scene, synthetic=[{**cube, "translate": [0.0, 0.0, -0.2]}]), 0, 4)
    assert key == cc.inputs_sha256(with_overrides(scene, render={"spp": 16, "gt_spp": 64}), 0, 4)
    # which runs are cached: the simulated rig, calibrated, no calibration file and no recording
    assert calibration_key(scene, RunOptions()) == key
    assert calibration_key(scene, RunOptions(rig_model="nominal")) is None
    assert calibration_key(scene, RunOptions(record=cc.cache_dir())) is None


def test_03_a_run_reuses_the_calibration_and_reports_the_same(variant, tmp_path, monkeypatch):
    """The first run calibrates and stores the calibration; the second finds it (no calibration steps in its
    progress total), says so in its report, copies the calibration's files and gives the same report as the
    first, noise included: the rig's random streams are restored to where the calibrating run's stood (negative
    control: without that, the same run draws other noise and its metrics differ). --recalibrate calibrates
    again; a corrupt entry is named in one warning and the run calibrates again and writes it anew.

    The calibration is the rig file's own values (the tiny rig is too coarse to calibrate), taken after two LF
    captures, so that it uses the rig's noise as a real calibration does."""
    from lftransfer.runs import rigs
    from lftransfer.sim.rig import SimRig
    from tests.small import nominal_calibration

    scene = load_scene(write_tiny_scene(tmp_path / "tiny.toml", view=(32, 24), gt_spp=4))
    calls = []

    def calibrate(rig, ps, *, progress=None, rigs=()):
        calls.append(ps)
        rig.capture_lf()
        rig.capture_lf()
        return nominal_calibration(scene)

    monkeypatch.setattr(rigs, "calibrate", calibrate)
    options = RunOptions(settings=Overrides(bounces=1), capture_spp=1, floor=False)
    assert will_calibrate(scene, options)
    first = run_scene(scene, tmp_path / "first", options)
    assert len(calls) == 1 and first["rig_model"] == "calibrated" and "calibration" in first["timings_s"]
    key = calibration_key(scene, options)
    assert isinstance(cc.read_entry(key), cc.CachedCalibration) and not will_calibrate(scene, options)
    recalibrating = RunOptions(**{**options.__dict__, "recalibrate": True})
    assert will_calibrate(scene, recalibrating) and count_run_steps(scene, options) < count_run_steps(scene,
                                                                                                   recalibrating)
    seen = []
    second = run_scene(scene, tmp_path / "second", options, progress=lambda msg, done: seen.append(done))
    assert len(calls) == 1 and max(seen) <= count_run_steps(scene, options)
    assert second["rig_model"].startswith("calibrated (reused from the calibration cache")
    assert "--recalibrate" in second["rig_model"] and "calibration" not in second["timings_s"]
    for name in cc.FILES:
        if (tmp_path / "first" / name).is_file():
            assert (tmp_path / "second" / name).read_bytes() == (tmp_path / "first" / name).read_bytes(), name
    metrics = ("cross_transfer_rel_error", "psnr_db", "psnr_objects_db", "calibration_errors")
    assert all(second[m] == first[m] for m in metrics), [(m, first[m], second[m]) for m in metrics]

    with monkeypatch.context() as m:                       # negative control: the noise state left as it is
        m.setattr(SimRig, "restore_noise_state", lambda self, state: None)
        unrestored = run_scene(scene, tmp_path / "unrestored", options)
    assert unrestored["psnr_db"] != first["psnr_db"]

    again = run_scene(scene, tmp_path / "again", recalibrating)
    assert len(calls) == 2 and again["rig_model"] == "calibrated" and again["psnr_db"] == first["psnr_db"]

    entry = cc.read_entry(key)
    entry.calibration_file.write_text(entry.calibration_file.read_text() + " ")
    fixed = run_scene(scene, tmp_path / "fixed", options)
    assert len(calls) == 3 and fixed["rig_model"] == "calibrated"
    assert any("calibration cache entry" in w and "calibrating again" in w for w in fixed["warnings"])
    assert isinstance(cc.read_entry(key), cc.CachedCalibration)            # written anew
