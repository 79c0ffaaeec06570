"""Calibration accuracy over several hidden truths: every step through the simulated rig, errors per seed.

For each seed the simulated rig is built as the rig file says plus deviations drawn from that seed
(:func:`lftransfer.sim.truth.perturbed_rig`, with the point light moved as in
:func:`lftransfer.sim.truth.true_light_scene`, which the last step measures); the pipeline calibrates it from
images alone
(:func:`lftransfer.calibration.rig.calibrate_rig`) and the verification code compares the result with the
hidden truth (:func:`lftransfer.sim.calibration_errors.calibration_errors`).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from typing import Callable, Sequence

import numpy as np

from lftransfer.runs.cluster import ClusterSpec, Worker
from lftransfer.calibration.rig import calibrate_rig
from lftransfer.calibration.targets import TARGETS as CALIBRATION_TARGETS, target
from lftransfer.sim.oracle import open_simulated_rig

__all__ = ["TARGETS", "CalibrationSeeds", "QuantitySummary", "SeedCalibration", "calibrate_seed", "calibration_seeds",
           "markdown_table"]

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
    "light_residual_rms": ("relative", "point lights: the fit's residual, RMS (the worst light)"),
}


@dataclass(frozen=True)
class SeedCalibration:
    """One hidden truth calibrated.

    Attributes:
        seed: the hidden truth's seed.
        errors: quantity (a key of :data:`TARGETS` or :data:`OTHERS`) -> its error against the truth.
        calibration_s: wall time of the calibration, s.
    """

    seed: int
    errors: dict[str, float]
    calibration_s: float


@dataclass(frozen=True)
class QuantitySummary:
    """One quantity over the seeds.

    Attributes:
        worst: largest magnitude over the seeds.
        mean: mean magnitude.
        target: the project's bound (:mod:`lftransfer.calibration.targets`), None where it has none.
        met: every seed meets the target (None without a target).
    """

    worst: float
    mean: float
    target: float | None = None
    met: bool | None = None


@dataclass(frozen=True)
class CalibrationSeeds:
    """Calibration accuracy over several hidden truths (``lft calibrate seeds``).

    Attributes:
        seeds: per seed, in the order asked for.
        summary: quantity -> :class:`QuantitySummary` (quantities every seed measured).
        resolution: the devices' sizes and the lenslet lattice of the scene calibrated.
    """

    seeds: list[SeedCalibration]
    summary: dict[str, QuantitySummary]
    resolution: dict[str, list[int]]

    def to_json(self) -> dict:
        """``calibration_errors.json``: per seed its errors and ``calibration_s``, the summary, the resolution."""
        seeds = {str(r.seed): {**r.errors, "calibration_s": round(r.calibration_s, 1)} for r in self.seeds}
        summary = {k: {f: v for f, v in asdict(q).items() if v is not None} for k, q in self.summary.items()}
        return {"seeds": seeds, "summary": summary, "resolution": self.resolution}


def calibrate_seed(scene, seed: int, *, progress: Callable[[str], None] | None = None) -> SeedCalibration:
    """Build the simulated rig of hidden truth ``seed``, calibrate it from images and measure every error.

    Args:
        scene: the scene (its rig file).
        seed: the hidden truth's seed (also the operator's hand errors').
        progress: called with a message per calibration step.
    """
    say = progress or (lambda msg: None)
    rig, oracle = open_simulated_rig(scene, seed)
    t = time.perf_counter()
    cal = calibrate_rig(rig, scene.synthetic_part(), progress=lambda msg: say(f"seed {seed}: {msg}"))
    errors = oracle.calibration_errors(cal).to_json()
    placement = cal.diagnostics["pose"]["board_placement"]
    errors["board_depth_mm"] = placement["depth_mm"]
    errors["board_tilt_deg"] = placement["tilt_deg"]
    if cal.lights:
        errors["light_residual_rms"] = max(fit.residual_rms for fit in cal.lights)
    return SeedCalibration(seed=int(seed), errors={k: float(v) for k, v in errors.items()},
                           calibration_s=time.perf_counter() - t)


class SeedWorker(Worker):
    """A cluster worker that calibrates hidden truths of one scene (:class:`lftransfer.runs.cluster.WorkerPool`)."""

    def __init__(self, scene, threads: int | None = None) -> None:
        super().__init__(threads)
        self.scene = scene

    def calibrate(self, seed: int) -> SeedCalibration:
        return calibrate_seed(self.scene, seed)


def calibration_seeds(scene, seeds: Sequence[int], *, progress: Callable[[str], None] | None = None,
                      cluster: ClusterSpec | None = None) -> CalibrationSeeds:
    """Calibrate the simulated rig once per hidden truth and measure every error.

    Args:
        scene: the scene (its rig file).
        seeds: hidden-truth seeds.
        progress: called with a message per calibration step (on a cluster: per seed finished).
        cluster: calibrate the seeds in parallel on a Ray cluster (:mod:`lftransfer.runs.cluster`); None: one
            after the other here. Each seed's result is the same either way.

    Returns:
        :class:`CalibrationSeeds`.
    """
    seeds = [int(s) for s in seeds]
    if cluster is None:
        results = [calibrate_seed(scene, s, progress=progress) for s in seeds]
    else:
        from lftransfer.runs.cluster import WorkerPool, connect

        say = progress or (lambda msg: None)
        by_seed = {}
        with connect(cluster) as info:
            pool = WorkerPool(SeedWorker, (scene,), info, min(cluster.workers or info.default_workers(), len(seeds)))
            for (seed,), result in pool.map("calibrate", [(s,) for s in seeds]):
                by_seed[seed] = result
                say(f"seed {seed}: calibrated in {result.calibration_s:.0f} s")
        results = [by_seed[s] for s in seeds]
    summary = {}
    for key in list(TARGETS) + list(OTHERS):
        if any(key not in r.errors for r in results):        # not measured (a scene without a point light)
            continue
        values = np.abs([r.errors[key] for r in results])
        met = all(target(key).met(v) for v in values) if key in TARGETS else None
        summary[key] = QuantitySummary(worst=float(values.max()), mean=float(values.mean()),
                                       target=TARGETS[key][0] if key in TARGETS else None, met=met)
    resolution = {"lf_camera": list(scene.rig.lf_camera), "projector": list(scene.rig.projector),
                  "view": list(scene.view.resolution), "lenslets": [scene.rig.rows, scene.rig.cols]}
    return CalibrationSeeds(seeds=results, summary=summary, resolution=resolution)


def markdown_table(result: CalibrationSeeds) -> str:
    """The per-seed errors as a Markdown table (one row per quantity, one column per seed)."""
    head = "| quantity | target | " + " | ".join(f"seed {r.seed}" for r in result.seeds) + " | worst |"
    rows = [head, "|" + "---|" * (len(result.seeds) + 3)]

    def fmt(v: float) -> str:
        return f"{v:.3g}" if abs(v) >= 1e-3 else f"{v:.1e}"

    for key, (target_value, unit, what) in TARGETS.items():
        if key not in result.summary:
            continue
        vals = [r.errors[key] for r in result.seeds]
        ok = "yes" if result.summary[key].met else "**no**"
        rows.append(f"| {what} ({unit}) | <= {target_value:g} | " + " | ".join(fmt(v) for v in vals)
                    + f" | {fmt(max(map(abs, vals)))} ({ok}) |")
    for key, (unit, what) in OTHERS.items():
        if key not in result.summary:
            continue
        vals = [r.errors[key] for r in result.seeds]
        label = f"{what} ({unit})" if unit else what
        rows.append(f"| {label} | | " + " | ".join(fmt(v) for v in vals) + f" | {fmt(max(map(abs, vals)))} |")
    times = [r.calibration_s for r in result.seeds]
    rows.append("| calibration time (s) | | " + " | ".join(f"{t:.0f}" for t in times) + f" | {max(times):.0f} |")
    return "\n".join(rows) + "\n"
