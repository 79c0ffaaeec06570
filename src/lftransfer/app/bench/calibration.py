"""Calibration accuracy over several hidden truths: every step through the simulated rig, errors per seed.

For each seed the simulated rig is built as the rig file says plus deviations drawn from that seed
(:func:`lftransfer.sim.truth.perturbed_rig`, with the point light moved as in
:func:`lftransfer.sim.truth.true_light_scene`, which the last step measures); the pipeline calibrates it from
images alone
(:func:`lftransfer.calibration.rig.calibrate_rig`) and the verification code compares the result with the
hidden truth (:func:`lftransfer.sim.verify.calibration_errors`).
"""

from __future__ import annotations

import time
from typing import Callable, Sequence

import numpy as np

from lftransfer.calibration.rig import calibrate_rig
from lftransfer.calibration.targets import TARGETS as CALIBRATION_TARGETS, target
from lftransfer.sim.rig import SimRig
from lftransfer.sim.truth import hidden_world
from lftransfer.sim.verify import calibration_errors

__all__ = ["TARGETS", "calibration_seeds", "markdown_table"]

# quantity -> (largest allowed value over the seeds, unit, what it measures): calibration/targets.py
TARGETS = {t.key: (t.bound, t.unit, t.what) for t in CALIBRATION_TARGETS}
# reported too, without a target in the issue
OTHERS = {
    "ray_direction_rms_deg": ("deg", "ray of each LF camera pixel, in the world"),
    "pitch_rel_error": ("", "lens pitch (relative)"),
    "distortion_k1_rms": ("", "per-lenslet k1"),
    "projector_mixing_rel_error": ("", "projector brightness x cross-talk (relative)"),
    "black_level_error": ("of max", "projector black level"),
    "exposure_rel_error": ("", "LF camera exposure (relative)"),
    "camera_gain_rel_rms": ("", "LF camera exposure x vignetting per pixel (relative RMS)"),
    "board_depth_mm": ("mm", "pose board: measured off the asked-for plane (operator's hand error)"),
    "board_tilt_deg": ("deg", "pose board: measured tilt from the asked-for plane"),
    "light_residual_rms": ("relative", "point light: the fit's residual, RMS"),
}


def calibration_seeds(scene, seeds: Sequence[int], *, progress: Callable[[str], None] | None = None) -> dict:
    """Calibrate the simulated rig once per hidden truth and measure every error.

    Args:
        scene: the scene (its rig file).
        seeds: hidden-truth seeds.
        progress: called with a message per calibration step.

    Returns:
        JSON-ready dict: ``seeds`` (per seed: the errors and the calibration time), ``summary`` (per quantity:
        worst and mean over the seeds, target and whether every seed meets it).
    """
    say = progress or (lambda msg: None)
    per_seed = {}
    for seed in seeds:
        world, truth = hidden_world(scene, seed)
        rig = SimRig(world, truth=truth, operator_seed=seed)
        t = time.perf_counter()
        cal = calibrate_rig(rig, scene.synthetic_part(), progress=lambda msg, s=seed: say(f"seed {s}: {msg}"))
        errors = calibration_errors(cal, rig.truth,
                                    true_light=None if world.light is None else world.light.position)
        placement = cal.diagnostics["pose"]["board_placement"]
        errors["board_depth_mm"] = placement["depth_mm"]
        errors["board_tilt_deg"] = placement["tilt_deg"]
        if cal.light is not None:
            errors["light_residual_rms"] = cal.light.residual_rms
        errors["calibration_s"] = round(time.perf_counter() - t, 1)
        per_seed[str(seed)] = errors
    summary = {}
    for key in list(TARGETS) + list(OTHERS):
        if any(key not in e for e in per_seed.values()):        # not measured (a scene without a point light)
            continue
        values = np.abs([e[key] for e in per_seed.values()])
        entry = {"worst": float(values.max()), "mean": float(values.mean())}
        if key in TARGETS:
            entry.update(target=TARGETS[key][0], met=all(target(key).met(v) for v in values))
        summary[key] = entry
    return {"seeds": per_seed, "summary": summary,
            "resolution": {"lf_camera": list(scene.rig.lf_camera), "projector": list(scene.rig.projector),
                           "view": list(scene.view.resolution), "lenslets": [scene.rig.rows, scene.rig.cols]}}


def markdown_table(result: dict) -> str:
    """The per-seed errors as a Markdown table (one row per quantity, one column per seed)."""
    seeds = list(result["seeds"])
    head = "| quantity | target | " + " | ".join(f"seed {s}" for s in seeds) + " | worst |"
    rows = [head, "|" + "---|" * (len(seeds) + 3)]

    def fmt(v: float) -> str:
        return f"{v:.3g}" if abs(v) >= 1e-3 else f"{v:.1e}"

    for key, (target, unit, what) in TARGETS.items():
        if key not in result["summary"]:
            continue
        vals = [result["seeds"][s][key] for s in seeds]
        ok = "yes" if result["summary"][key]["met"] else "**no**"
        rows.append(f"| {what} ({unit}) | <= {target:g} | " + " | ".join(fmt(v) for v in vals)
                    + f" | {fmt(max(map(abs, vals)))} ({ok}) |")
    for key, (unit, what) in OTHERS.items():
        if key not in result["summary"]:
            continue
        vals = [result["seeds"][s][key] for s in seeds]
        label = f"{what} ({unit})" if unit else what
        rows.append(f"| {label} | | " + " | ".join(fmt(v) for v in vals) + f" | {fmt(max(map(abs, vals)))} |")
    times = [result["seeds"][s]["calibration_s"] for s in seeds]
    rows.append("| calibration time (s) | | " + " | ".join(f"{t:.0f}" for t in times) + f" | {max(times):.0f} |")
    return "\n".join(rows) + "\n"
