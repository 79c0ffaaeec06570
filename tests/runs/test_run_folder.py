"""A run folder says whether it is complete and never mixes two runs: an earlier run's outputs and temporary
files are removed before a run writes, status.json is written first and last, Ctrl-C is reported."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from lftransfer.app.cli import app
from lftransfer.runs.run_folder import OUTPUT_FILES, clear_run_folder, remove_temporaries
from lftransfer.scenes import load_scene
from tests.small import nominal_calibration, write_tiny_scene
from tests.app.test_cli_errors import _one_line_error

runner = CliRunner()
TEMPORARIES = (".composite.k2j3h4.png", ".report.abc_12.json", ".status.x1.json", ".lft-probe-9q")


def _old_run(out):
    """A folder as an earlier (complete) run left it, plus temporary files of an interrupted write."""
    out.mkdir(parents=True, exist_ok=True)
    for name in OUTPUT_FILES:
        (out / name).write_text("old")
    for name in TEMPORARIES:
        (out / name).write_text("partial")
    (out / "my-notes.txt").write_text("mine")
    (out / ".hidden.cfg").write_text("mine too")


def test_01_clear_removes_outputs_and_temporaries_only(tmp_path):
    _old_run(tmp_path)
    keep = tmp_path / "calibration.json"
    removed = clear_run_folder(tmp_path, keep=[keep])
    assert keep.exists() and keep.read_text() == "old"
    assert {p.name for p in removed} == (set(OUTPUT_FILES) - {"calibration.json"}) | set(TEMPORARIES)
    assert sorted(p.name for p in tmp_path.iterdir()) == [".hidden.cfg", "calibration.json", "my-notes.txt"]
    assert clear_run_folder(tmp_path / "missing") == [] and remove_temporaries(tmp_path / "missing") == []


def test_02_interrupted_rerun_leaves_no_old_report_and_no_temporaries(tmp_path, monkeypatch):
    """Ctrl-C during a rerun in a used folder: one line, exit code 130, status 'interrupted', no report of the
    earlier run beside this run's files, no temporary file; the run's own calibration file stays."""
    scene = write_tiny_scene(tmp_path / "tiny.toml")
    out = tmp_path / "out"
    _old_run(out)
    calibration = nominal_calibration(load_scene(scene)).write(out / "calibration.json")

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("lftransfer.runs.pipeline.run_transfer", interrupted)
    result = runner.invoke(app, ["run", str(scene), "--out", str(out), "--calibration", str(calibration),
                                 "--exact-rig"])
    line = _one_line_error(result, code=130, progress=True)
    assert "no light section" in result.stderr          # the file has none: said, not silently the scene's light
    assert "interrupted" in line and str(out / "status.json") in line
    status = json.loads((out / "status.json").read_text())
    assert status["state"] == "interrupted"
    left = sorted(p.name for p in out.iterdir())
    assert "report.json" not in left and "composite.png" not in left
    assert not [n for n in left if n.startswith(".") and n != ".hidden.cfg"], left
    assert json.loads(calibration.read_text())["format"] == "lftransfer-calibration/1"   # not removed, not rewritten


def test_03_failed_run_says_failed(tmp_path, monkeypatch):
    from lftransfer.runs.pipeline import RunOptions, run_scene

    def broken(*args, **kwargs):
        raise RuntimeError("the projector caught fire")

    monkeypatch.setattr("lftransfer.runs.pipeline.run_transfer", broken)
    out = tmp_path / "out"
    _old_run(out)
    with pytest.raises(RuntimeError):
        run_scene(load_scene(write_tiny_scene(tmp_path / "t.toml")), out,
                  RunOptions(truth_seed=None, rig_model="nominal"))
    status = json.loads((out / "status.json").read_text())
    assert status["state"] == "failed" and "caught fire" in status["error"]
    assert not (out / "report.json").exists()
