"""The accuracy targets of calibration, defined once (lftransfer.calibration.targets)."""

from __future__ import annotations

import math

import pytest

from lftransfer.calibration.targets import TARGETS, target


def test_01_one_target_per_error_with_the_documented_bounds():
    keys = [t.key for t in TARGETS]
    assert len(keys) == len(set(keys))
    bounds = {t.key: t.bound for t in TARGETS}
    assert bounds == {"lenslet_centre_rms_px": 0.1, "projector_mapping_rms_px": 0.5, "pose_position_rms_mm": 1.0,
                      "pose_position_max_mm": 1.0, "pose_rotation_deg": 0.2, "camera_response_error": 0.01,
                      "projector_response_error": 0.01, "exposure_rel_error": 0.01,
                      "light_position_error_mm": 1.0}


def test_02_met_is_on_the_magnitude_and_never_nan():
    t = target("pose_rotation_deg")
    assert t.met(0.2) and t.met(-0.19) and not t.met(0.2001) and not t.met(-0.3)
    assert not t.met(math.nan) and not t.met(math.inf)
    with pytest.raises(KeyError, match="no calibration target for 'black_level_error'"):
        target("black_level_error")


def test_03_the_report_and_the_seed_table_read_the_same_targets():
    from lftransfer.runs.bench.calibration import TARGETS as SEED_TARGETS
    from lftransfer.reports.calibration_report import TARGETS as REPORT_TARGETS

    assert {k: v[0] for k, v in SEED_TARGETS.items()} == {t.key: t.bound for t in TARGETS}
    assert {k: v.bound for k, v in REPORT_TARGETS.items()} == {t.key: t.bound for t in TARGETS}
