"""``lft calibrate seeds``: the typed result over seeds, its summary against the targets, its JSON and table."""

from __future__ import annotations

import math

import pytest

from lftransfer.runs.bench import calibration as seeds_module
from lftransfer.runs.bench.calibration import SeedCalibration, calibration_seeds, markdown_table
from lftransfer.calibration.targets import TARGETS
from lftransfer.scenes import builtin_scene, load_scene


def _fake(errors_by_seed):
    def calibrate_seed(scene, seed, *, progress=None):
        return SeedCalibration(seed=seed, errors=dict(errors_by_seed[seed]), calibration_s=10.0 * seed)
    return calibrate_seed


def test_01_summary_targets_json_and_table(monkeypatch):
    """The worst seed decides whether a target is met; quantities a seed did not measure are left out."""
    pose = next(t for t in TARGETS if t.key == "pose_position_rms_mm")
    errors = {1: {"pose_position_rms_mm": 0.5 * pose.bound, "board_depth_mm": -2.0, "light_position_error_mm": 0.1},
              2: {"pose_position_rms_mm": -2.0 * pose.bound, "board_depth_mm": 1.0}}
    monkeypatch.setattr(seeds_module, "calibrate_seed", _fake(errors))
    result = calibration_seeds(load_scene(builtin_scene("fig4")), [2, 1])
    assert [r.seed for r in result.seeds] == [2, 1]
    s = result.summary["pose_position_rms_mm"]
    assert (s.worst, s.mean, s.target, s.met) == (2.0 * pose.bound, 1.25 * pose.bound, pose.bound, False)
    assert result.summary["board_depth_mm"].target is None and result.summary["board_depth_mm"].worst == 2.0
    assert "light_position_error_mm" not in result.summary        # seed 2 has no light: not summarised
    data = result.to_json()
    assert data["seeds"]["1"]["calibration_s"] == 10.0 and data["seeds"]["2"]["board_depth_mm"] == 1.0
    assert data["summary"]["pose_position_rms_mm"]["met"] is False
    assert "target" not in data["summary"]["board_depth_mm"]
    table = markdown_table(result)
    assert "| seed 2 | seed 1 |" in table and "(**no**)" in table
    assert table.strip().splitlines()[-1].startswith("| calibration time (s) | | 20 | 10 | 20 |")


def test_02_a_nan_error_never_meets_its_target(monkeypatch):
    monkeypatch.setattr(seeds_module, "calibrate_seed", _fake({3: {"pose_position_rms_mm": math.nan}}))
    result = calibration_seeds(load_scene(builtin_scene("fig4")), [3])
    assert result.summary["pose_position_rms_mm"].met is False
    with pytest.raises(KeyError):
        result.summary["pose_rotation_deg"]
