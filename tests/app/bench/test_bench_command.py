"""The ``lft bench`` command: options checked first, the live step timed, the results and settings as JSON."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from lftransfer.runs import rigs
from lftransfer.app.cli import app
from lftransfer.scenes import load_scene
from lftransfer.transfer.live import LiveTransfer
from tests.small import nominal_calibration, write_tiny_scene

runner = CliRunner()


def _invoke(args):
    return runner.invoke(app, [str(a) for a in args], env={"COLUMNS": "200"})


def test_01_quick_bench_writes_json_with_settings(tmp_path, monkeypatch):
    calls = []
    step = LiveTransfer.step
    monkeypatch.setattr(LiveTransfer, "step", lambda self, t: calls.append(t) or step(self, t))
    out = tmp_path / "bench.json"
    result = _invoke(["bench", "--quick", "--rig-model", "oracle", "--iterations", "1", "--no-peer", "--no-accuracy",
                      "--json", out])
    assert result.exit_code == 0, (result.output, result.exception)
    assert len(calls) == 3                                             # 2 warm-up + 1 timed frame
    data = json.loads(out.read_text())
    assert data["pipeline_iteration_ms"] >= data["floor_ms"] > 0
    s = data["settings"]
    for key in ("scene", "resolution", "angular_samples", "lf_spp", "view_spp", "lighting_model", "reconstruction",
                "renderer", "rig_model", "variant"):
        assert s[key] is not None, key
    assert s["quick"] is True
    assert s["command"] == "lft bench --quick --iterations 1 --rig-model oracle --no-accuracy --no-peer"
    assert "pipeline_iteration_ms" in result.stdout and "floor_ms" in result.stdout
    assert "not what users run" in result.stdout


def test_02_calibrates_first_and_says_so(tmp_path, monkeypatch):
    scene = write_tiny_scene(tmp_path / "tiny.toml")
    monkeypatch.setattr(rigs, "calibrate",
                        lambda rig, s, progress=None, rigs=(): nominal_calibration(load_scene(scene)))
    result = _invoke(["bench", "--scene", scene, "--iterations", "1", "--no-peer", "--no-accuracy"])
    assert result.exit_code == 0, (result.output, result.exception)
    assert "calibrates the simulated rig first" in result.stderr and "--calibration FILE" in result.stderr
    assert "calibrated (by the bench" in result.stdout


def test_03_calibration_file_is_used(tmp_path):
    scene = write_tiny_scene(tmp_path / "tiny.toml")
    cal = nominal_calibration(load_scene(scene)).write(tmp_path / "calibration.json")
    out = tmp_path / "b.json"
    result = _invoke(["bench", "--scene", scene, "--calibration", cal, "--iterations", "1", "--no-peer",
                      "--no-accuracy", "--json", out])
    assert result.exit_code == 0, (result.output, result.exception)
    assert "calibrates the simulated rig first" not in result.stderr
    s = json.loads(out.read_text())["settings"]
    assert s["rig_model"] == f"calibrated (calibration file {cal})" and s["calibration_file"] == str(cal)
    assert f"--calibration {cal}" in s["command"]


def test_04_bad_options_are_one_line_errors(tmp_path):
    scene = write_tiny_scene(tmp_path / "tiny.toml")
    for args, words in ((["--calibration", tmp_path / "none.json"], "--calibration"),
                        (["--rig-model", "guessed"], "--rig-model"),
                        (["--lighting-model", "flat"], "--lighting-model"),
                        (["--reconstruction", "cubic"], "--reconstruction"),
                        (["--renderer", "gpu"], "--renderer"),
                        (["--json", tmp_path], "--json")):
        result = _invoke(["bench", "--scene", scene, *args])
        lines = [line for line in result.stderr.splitlines() if line.strip() and line != "lft bench: starting"]
        assert result.exit_code == 2 and len(lines) == 1 and lines[0].startswith("error: "), (args, result.stderr)
        assert words in lines[0]
