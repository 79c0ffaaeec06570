"""The effect curve of ``lft render`` (lftransfer.runs.effects): the scene's [effect] measured at each verified
frame, light field transfer beside the ground truth, written as effect.json and effect.png."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lftransfer.runs.effects import EffectCurve, EffectPoint, verify_exchange
from lftransfer.runs.pipeline import RunOptions
from lftransfer.scenes import quick_scene
from lftransfer.runs.sequence import SequenceOptions, render_sequence
from lftransfer.scenes import builtin_scene, load_scene, with_overrides
from lftransfer.settings import Overrides
from lftransfer.sim.effects import EffectMeasure


def _approaching_scene():
    """fig4 small, the synthetic cube moving 3 cm towards the array over 3 frames; the effect measured is the
    light the cube adds to the real block."""
    scene = quick_scene(load_scene(builtin_scene("fig4")))
    cube = scene.synthetic[0].model_dump()
    x, y, z = cube["translate"]
    cube["keyframes"] = [{"time_s": 0.0, "translate": [x, y, z - 0.03]}, {"time_s": 0.5}]
    scene = with_overrides(scene, view={"resolution": [128, 96]}, render={"gt_spp": 64},
                           rig={"lf_camera": [256, 192], "projector": [256, 192], "angular_samples": 8},
                           animation={"duration_s": 0.5, "fps": 4}, synthetic=[cube])
    return scene.model_validate({**scene.model_dump(), "effect": {"kind": "reflection", "on": "red block",
                                                                   "by": "green cube"}})


def test_01_reflection_curve_against_ground_truth(variant, tmp_path):
    """Every verified frame gets a point; transfer and ground truth agree on the light the cube adds to the block
    (within 30 % at 64 ground-truth samples), and it grows as the cube approaches in both."""
    scene = _approaching_scene()
    out = tmp_path / "seq"
    options = RunOptions(rig_model="oracle", truth_seed=None)
    report = render_sequence(scene, out, options, SequenceOptions(mode="converged", frames=3, verify_every=2))
    check = verify_exchange(scene, out, options, report)
    curve = check.effect
    assert [p.index for p in curve.points] == [0, 2]
    lft, gt = curve.values()["added_radiance"]
    assert np.all(gt > 0) and np.all(lft > 0)
    assert np.max(np.abs(lft - gt) / gt) < 0.3
    assert gt[1] > gt[0] and lft[1] > lft[0]
    assert curve.points[0].distance_m > curve.points[1].distance_m
    saved = json.loads((out / "effect.json").read_text())
    assert saved["kind"] == "reflection" and len(saved["points"]) == 2
    assert saved["worst_relative_error"]["added_radiance"] == pytest.approx(np.max(np.abs(lft - gt) / gt))
    assert (out / "effect.png").stat().st_size > 10_000
    # each verified frame gets its cross error in report.json (the transfer is close: 0 < error < 0.5)
    saved = json.loads((out / "report.json").read_text())
    errors = {f["index"]: f["metrics"]["cross_transfer_rel_error"] for f in saved["frames"] if f["metrics"]}
    assert errors == check.cross_errors and all(0 < e < 0.5 for e in errors.values())
    assert saved["summary"]["cross_transfer_rel_error_max"] == max(errors.values())
    # ... split by side: the two sides' squared errors, weighted by their cross terms, make up the whole
    for f in (f for f in saved["frames"] if f["metrics"]):
        m = f["metrics"]
        assert all(m[f"cross_{side}_rel_error"] is not None and m[f"cross_{side}_gt_noise_rel"] is not None
                   for side in ("real", "synthetic"))
        assert min(m["cross_real_rel_error"], m["cross_synthetic_rel_error"]) <= m["cross_transfer_rel_error"] \
            <= max(m["cross_real_rel_error"], m["cross_synthetic_rel_error"]) + 1e-9
    # ... and its fidelity floor (the run's default): the frame scored as the floors are, the real side's floor no
    # worse than the frame, the whole the two sides' root sum of squares
    for f in (f for f in saved["frames"] if f["metrics"]):
        m, floor = f["metrics"], f["fidelity_floor"]
        assert 0 < m["real_floor"] <= floor["real"]["transfer"] and 0 < m["synthetic_floor"] < 0.5
        assert m["fidelity_floor"] == pytest.approx(np.hypot(m["real_floor"], m["synthetic_floor"]))
        assert m["floor_transfer"] == pytest.approx(np.hypot(floor["real"]["transfer"], floor["synthetic"]["transfer"]))
        assert m["transfer_over_floor"] == pytest.approx(m["floor_transfer"] / m["fidelity_floor"])
    ratios = [f["metrics"]["transfer_over_floor"] for f in saved["frames"] if f["metrics"]]
    assert saved["summary"]["transfer_over_floor_max"] == max(ratios)


def test_02_no_verified_frame_checks_nothing(tmp_path):
    scene = load_scene(builtin_scene("fig4"))
    assert verify_exchange(scene, tmp_path, RunOptions(), {"frames": [{"index": 0, "metrics": None}]}) is None


def test_03_curve_errors_and_trend():
    def point(i, d, lft, gt):
        return EffectPoint(index=i, time_s=i, distance_m=d, transfer=EffectMeasure("shadow", contrast=lft[0],
                                                                                   penumbra_m=lft[1]),
                           truth=EffectMeasure("shadow", contrast=gt[0], penumbra_m=gt[1]))

    curve = EffectCurve(kind="shadow", on="head", by="planet",
                        points=[point(0, 0.3, (0.15, None), (0.1, None)),        # faint: 50 % off, not counted
                                point(1, 0.2, (0.24, None), (0.3, 0.02)),
                                point(2, 0.1, (0.5, 0.010), (0.5, 0.008)),
                                point(3, 0.05, (0.6, 0.005), (0.75, 0.004))])
    worst = curve.worst_relative_error()
    assert worst["contrast"] == pytest.approx(0.2) and worst["penumbra_m"] == pytest.approx(0.25)
    assert curve.trend() == {"contrast": 1.0, "penumbra_m": 1.0, "area_m2": None}    # no area given


def test_04_quiet_reference_of_a_frame(variant, tmp_path):
    """``--quiet-reference`` on a sequence: the verified frame's ground truth is rendered until its noise on the
    frame's cross term is at most a third of the error (64 samples per pixel leave it above the error), and the
    frame's metrics are taken against it."""
    scene = _approaching_scene()
    out = tmp_path / "seq"
    options = RunOptions(rig_model="oracle", truth_seed=None, floor=False,
                         settings=Overrides(quiet_reference=True))
    report = render_sequence(scene, out, options, SequenceOptions(mode="converged", frames=1, verify_every=1))
    plain = dict(report["frames"][0]["metrics"])
    verify_exchange(scene, out, options, report)
    saved = json.loads((out / "report.json").read_text())
    f = saved["frames"][0]
    reference, m = f["reference"], f["metrics"]
    assert reference["met"] and reference["ratio"] <= 1 / 3 and reference["spp"] > 64 and reference["rounds"] > 1
    assert m["reference_spp"] == reference["spp"] and m["cross_gt_noise_rel"] == pytest.approx(reference["noise"])
    assert m["cross_gt_noise_rel"] <= m["cross_transfer_rel_error"] / 3
    assert m["psnr_objects_db"] != plain["psnr_objects_db"]            # taken again against the quiet reference
    assert saved["summary"]["psnr_objects_db_min"] == m["psnr_objects_db"]
    assert saved["summary"]["references_met"] == saved["summary"]["references"] == 1
    assert "real_floor" not in m and "fidelity_floor" not in f         # floor=False
