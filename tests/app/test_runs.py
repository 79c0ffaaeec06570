"""Whole runs of the ``lft`` command on a tiny rig (a few seconds each): reusing a calibration file, degenerate
scenes, a ground truth too noisy for the error it measures, a rerun into a used folder."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from typer.testing import CliRunner

from lftransfer.app.cli import app
from lftransfer.scenes import load_scene
from tests.small import nominal_calibration, write_tiny_scene

runner = CliRunner()


def _strict_report(out) -> dict:
    """report.json, read as strict JSON (NaN or Infinity fail)."""
    def refuse(constant):
        raise AssertionError(f"report.json holds {constant}, which is not JSON")

    return json.loads((out / "report.json").read_text(), parse_constant=refuse)


@pytest.fixture(scope="module")
def calibrated_run(tmp_path_factory):
    """``lft run SCENE --calibration FILE`` on the tiny rig (the rig exactly as its file says, the calibration the
    file's own values), with 8 ground-truth samples per pixel and the reference left as noisy as that
    (``--no-quiet-reference``: the noise's warning is what some of these tests read)."""
    d = tmp_path_factory.mktemp("calibrated_run")
    scene = write_tiny_scene(d / "tiny.toml", gt_spp=8)
    calibration = nominal_calibration(load_scene(scene)).write(d / "calibration.json")
    out = d / "out"
    result = runner.invoke(app, ["run", str(scene), "--calibration", str(calibration), "--exact-rig", "--bounces",
                                 "1", "--no-quiet-reference", "--out", str(out)], env={"COLUMNS": "200"})
    return scene, calibration, out, result


def test_01_run_with_a_calibration_file(calibrated_run):
    """Item 1: the README's ``lft run SCENE.toml --calibration calibration.json`` works to the end."""
    scene, calibration, out, result = calibrated_run
    assert result.exit_code == 0, (result.output, result.exception)
    report = _strict_report(out)
    assert report["rig_model"] == f"calibration file {calibration}"
    assert report["calibration_errors"]["pose_position_rms_mm"] < 1e-6          # the file holds the exact rig
    assert "lenslet_centre_rms_px" not in report["calibration_errors"]          # a file has no spot fit
    assert "light field transfer ->" in result.stdout and "calibration_errors.pose_position_rms_mm" in result.stdout
    assert json.loads((out / "status.json").read_text())["state"] == "complete"
    for name in ("composite.png", "ground_truth.png", "calibration.json", "calibration_report.html", "error.png",
                 "cross_term.png"):
        assert (out / name).stat().st_size > 0, name
    assert next(iter(report)) == "verdict" and report["verdict"]["reading"]
    assert result.stdout.lstrip().startswith("verdict: ")


def test_06_pictures_of_the_error_show_the_error():
    """error.png is |composite - truth| and cross_term.png the two cross terms and their difference, on scales that
    show them: a composite off by a known patch shows that patch (and nothing where the images agree); the cross
    term's panels keep their signs (a shadow, light taken away, is below zero)."""
    from lftransfer.reports.report import cross_term_figure, error_figure

    truth = np.full((24, 32, 3), 0.2, np.float32)
    composite = truth.copy()
    composite[5:9, 10:14] += 0.05
    fig = error_figure(composite, truth)
    image = fig.axes[0].images[0].get_array()
    assert np.allclose(image[5:9, 10:14], 0.05, atol=1e-6) and np.all(image[:5] == 0)
    assert fig.axes[0].images[0].get_clim() == (0.0, pytest.approx(0.05, rel=1e-6))
    shadow = np.zeros_like(truth)
    shadow[10:14, 2:6] = -0.1
    fig = cross_term_figure(shadow * 0.8, shadow)
    panels = [ax.images[0].get_array() for ax in fig.axes if ax.images]
    assert len(panels) == 3 and panels[1].min() == pytest.approx(-0.1) and panels[2].max() == pytest.approx(0.02)
    lo, hi = fig.axes[0].images[0].get_clim()
    assert lo == -hi == pytest.approx(-0.1)


def test_02_noisy_ground_truth_is_named_in_terminal_and_report(calibrated_run):
    """Item 8: at 8 samples per pixel the ground truth's noise on the cross term exceeds half the error."""
    _, _, out, result = calibrated_run
    report = _strict_report(out)
    noise, error = report["cross_gt_noise_rel"], report["cross_transfer_rel_error"]
    assert noise > 0.5 * error
    assert report["gt_spp_needed"] > 8 and report["gt_spp_needed"] & (report["gt_spp_needed"] - 1) == 0
    (warning,) = [w for w in report["warnings"] if "own noise" in w]
    assert f"--gt-spp {report['gt_spp_needed']}" in warning
    terminal = " ".join(result.stderr.split())
    assert "warning: the ground truth's own noise on the cross term" in terminal
    assert f"--gt-spp {report['gt_spp_needed']}" in terminal


def test_03_rerun_into_a_used_folder_keeps_only_its_own_files(calibrated_run, tmp_path):
    """Item 6: a nominal run into the folder of the calibrated run leaves no calibration files of that run."""
    scene, _, out, _ = calibrated_run
    again = tmp_path / "again"
    shutil.copytree(out, again)
    result = runner.invoke(app, ["run", str(scene), "--rig-model", "nominal", "--exact-rig", "--bounces", "1",
                                 "--out", str(again)])
    assert result.exit_code == 0, result.output
    names = {p.name for p in again.iterdir()}
    assert not names & {"calibration.json", "calibration_report.html", "calibration_errors.json"}, names
    assert _strict_report(again)["rig_model"] == "nominal (rig file)"
    assert not [n for n in names if n.startswith(".")]


@pytest.mark.parametrize("kind, undefined", [
    ("zero light", {"psnr_db": "black", "cross_transfer_rel_error": "no cross term", "cross_term_rel_size": "black"}),
    # the block hides the light: the view sees nothing lit; the cross term (the block's shadow on the cube, which
    # the synthetic side alone would see lit) is still defined
    ("light reaches nothing", {"psnr_db": "black", "cross_term_rel_size": "black"}),
    ("synthetic objects only", {"cross_transfer_rel_error": "no cross term", "cross_gt_noise_rel": "no cross term"}),
])
def test_04_degenerate_scenes_write_images_and_null_metrics(tmp_path, kind, undefined):
    """Item 4: undefined metrics are null with a reason in strict JSON, the others are numbers; the images are
    written."""
    kw = {"zero light": {"intensity": (0.0, 0.0, 0.0)},
          "light reaches nothing": {"light": (0.0, -0.005, 0.08)},        # inside the real block
          "synthetic objects only": {"real": False}}[kind]
    scene = write_tiny_scene(tmp_path / "scene.toml", view=(32, 24), gt_spp=4, **kw)
    out = tmp_path / "out"
    result = runner.invoke(app, ["run", str(scene), "--rig-model", "nominal", "--exact-rig", "--bounces", "1",
                                 "--out", str(out)], env={"COLUMNS": "200"})
    assert result.exit_code == 0, (result.output, result.exception)
    report = _strict_report(out)
    for key, words in undefined.items():
        assert report[key] is None and words in report["undefined_metrics"][key], (key, report["undefined_metrics"])
    for key in ("psnr_db", "cross_transfer_rel_error", "cross_term_rel_size"):
        if key not in undefined:
            assert isinstance(report[key], float), (key, report[key])
    for name in ("composite.png", "composite.exr", "ground_truth.png", "bounces.png", "projected_lf.png"):
        assert (out / name).stat().st_size > 0, name
    shown = " ".join(result.stdout.split())
    assert all(f"{key} is undefined" in shown for key in undefined)


def test_05_demo_reports_its_negative_control(tmp_path, monkeypatch):
    """``lft demo`` runs the negative control (the rig file's nominal values on the same perturbed rig, the same
    ground truth) and reports it in report.json and one line of the summary. The Fig. 4 scene is swapped for the
    tiny rig here, and the oracle model stands in for calibration (seconds instead of minutes)."""
    scene = load_scene(write_tiny_scene(tmp_path / "tiny.toml", view=(32, 24), gt_spp=4))
    monkeypatch.setattr("lftransfer.app.cli.run.load", lambda path, quick: scene)
    out = tmp_path / "out"
    result = runner.invoke(app, ["demo", "--rig-model", "oracle", "--bounces", "1", "--out", str(out)],
                           env={"COLUMNS": "250"})
    assert result.exit_code == 0, (result.output, result.exception)
    report = _strict_report(out)
    shown = " ".join(result.stdout.split())
    for key in ("psnr_objects_db", "psnr_objects_db_direct_only"):
        assert isinstance(report[key], float) and key in shown
    control = report["negative_control"]
    assert control["rig_model"] == "nominal (rig file)" and "negative_control" not in report["undefined_metrics"]
    assert control["cross_error_margin"] == pytest.approx(control["cross_transfer_rel_error"]
                                                          - report["cross_transfer_rel_error"])
    assert report["timings_s"]["negative_control"] > 0
    (line,) = [ln for ln in result.stdout.splitlines() if "negative_control (nominal (rig file))" in ln]
    assert f"cross error {control['cross_transfer_rel_error']:.3g}" in line
    assert ("NOT measurably worse" in line) == (not control["measurably_worse"])
    assert any("negative control" in w for w in report["warnings"]) == (not control["measurably_worse"])


def test_06_negative_control_is_skipped_with_a_reason_where_it_cannot_tell_anything():
    from pathlib import Path

    from lftransfer.runs.pipeline import RigSpec, RunOptions, negative_control_skipped

    assert negative_control_skipped(RunOptions(negative_control=True), 2) is None
    assert negative_control_skipped(RunOptions(negative_control=True, rig_model="oracle"), 2) is None
    assert negative_control_skipped(RunOptions(rig_model="nominal", calibration=Path("c.json")), 2) is None
    for options, bounces, words in ((RunOptions(rig_model="nominal"), 2, "itself uses the nominal"),
                                    (RunOptions(truth_seed=None), 2, "--exact-rig"),
                                    (RunOptions(), 0, "0 bounces"),
                                    (RunOptions(verify=False), 2, "not verified"),
                                    (RunOptions(rig=RigSpec("replay", Path("session"))), 2, "simulated rig only")):
        assert words in negative_control_skipped(options, bounces), options


def test_07_an_animated_scene_says_which_moment_it_runs(tmp_path):
    """``lft run`` on an animated scene renders one moment and says which, in the terminal and the report (t = 0
    unless ``--time``); the cube is posed there (negative control: another moment gives another composite); --time
    on a still scene is refused in one line."""
    scene = write_tiny_scene(tmp_path / "moving.toml", gt_spp=4)
    scene.write_text(scene.read_text() + "[[synthetic.keyframes]]\ntime_s = 0.0\n[[synthetic.keyframes]]\n"
                     "time_s = 1.0\ntranslate = [0.02, 0.0, -0.08]\n[animation]\nduration_s = 1.0\nfps = 4\n")
    common = ["--calibration", str(nominal_calibration(load_scene(scene)).write(tmp_path / "cal.json")),
              "--exact-rig", "--bounces", "1", "--no-quiet-reference", "--no-floor"]
    start = runner.invoke(app, ["run", str(scene), *common, "--out", str(tmp_path / "t0")])
    later = runner.invoke(app, ["run", str(scene), *common, "--time", "1", "--out", str(tmp_path / "t1")])
    for result, t in ((start, "0"), (later, "1")):
        assert result.exit_code == 0, (result.output, result.exception)
        assert f"this run renders its moment t = {t} s" in " ".join(result.stderr.split())
    report = _strict_report(tmp_path / "t1")
    assert any("t = 1 s" in w for w in report["warnings"])
    a = (tmp_path / "t0" / "composite.exr").read_bytes()
    assert a != (tmp_path / "t1" / "composite.exr").read_bytes()
    still = write_tiny_scene(tmp_path / "still.toml", gt_spp=4)
    refused = runner.invoke(app, ["run", str(still), "--time", "1", "--out", str(tmp_path / "s")])
    assert refused.exit_code == 2 and "the scene is still" in " ".join(refused.stderr.split())
