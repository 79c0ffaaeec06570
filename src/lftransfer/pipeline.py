"""One complete run: simulated rig, transfer, ground truth, metrics and output files.

This is what ``lft run`` and ``lft demo`` call. It reports progress through a callback and never prints.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable


from lftransfer.calibration.rig import calibrate_rig, count_calibration_steps, load_calibration
from lftransfer.composite import composite
from lftransfer.report import write_json, write_outputs
from lftransfer.rig.model import nominal_rig
from lftransfer.rig.sim import SimRig
from lftransfer.rig.truth import hidden_world
from lftransfer.transfer.bounce import TransferSettings, count_steps, resolve_renderer, run_transfer
from lftransfer.verify import calibration_errors, evaluate, render_ground_truth

Progress = Callable[[str, int], None]   # (description, steps done so far)


@dataclass(frozen=True)
class RunOptions:
    """Options of a run.

    Attributes:
        bounces: number of bounces N.
        lighting_model: the model used for the outputs ("area", "point" or "prefiltered").
        compare_models: further lighting models whose cross-transfer error is also measured (full reruns).
        gt_spp: samples per pixel of each ground-truth render (None: the scene's ``render.gt_spp``).
        capture_spp: rays per LF camera pixel in the simulated rig.
        use_cache: cache ground-truth renders.
        renderer: synthetic renderer, "auto" (fast path where the scene allows), "fast" or "exact".
        truth_seed: None: the simulated rig is built exactly as the rig file says; a seed: it is built with
            deviations drawn from that seed (:func:`lftransfer.rig.truth.perturbed_rig`), and its point light
            stands away from the file's position (:func:`lftransfer.rig.truth.true_light_scene`).
        rig_model: what the pipeline knows of the rig: ``"calibrated"`` (run every calibration step through the
            rig first), ``"nominal"`` (the rig file's values, uncalibrated) or ``"oracle"`` (the simulated rig's
            hidden truth: a verification baseline, what perfect calibration would reach; the point light stays
            where the scene file says, as no calibration step measures it).
        calibration: a calibration file to use instead of calibrating (``rig_model`` is then ignored).
    """

    bounces: int = 2
    lighting_model: str | None = None
    compare_models: tuple[str, ...] = ("point",)
    gt_spp: int | None = None
    capture_spp: int = 4
    use_cache: bool = True
    renderer: str = "auto"
    truth_seed: int | None = 0
    rig_model: str = "calibrated"
    calibration: Path | None = None


def quick_scene(scene):
    """The same scene at a small resolution (for ``--quick``): every device at a quarter size."""
    from lftransfer.scenes import with_overrides

    rig, view, render = scene.rig, scene.view, scene.render
    return with_overrides(
        scene,
        rig={"lf_camera": [rig.lf_camera[0] // 4, rig.lf_camera[1] // 4],
             "projector": [rig.projector[0] // 4, rig.projector[1] // 4],
             "angular_samples": max(8, rig.angular_samples // 3)},
        view={"resolution": [view.resolution[0] // 4, view.resolution[1] // 4]},
        render={"gt_spp": max(16, render.gt_spp // 4)},
    )


RIG_MODELS = ("calibrated", "nominal", "oracle")


def _calibrates(options: RunOptions) -> bool:
    return options.calibration is None and options.rig_model == "calibrated"


def count_run_steps(scene, options: RunOptions) -> int:
    """Progress steps of :func:`run_scene` (set-up, calibration, transfer, 6 ground-truth renders unless cached,
    reruns with the other lighting models, writing), for a progress bar."""
    primary = count_steps(TransferSettings(bounces=options.bounces))
    other = count_steps(TransferSettings(bounces=options.bounces, bounce_views=False))
    calibration = (count_calibration_steps(scene) if _calibrates(options) else 0) \
        + (1 if _calibrates(options) or options.calibration is not None else 0)
    return 1 + calibration + primary + 6 + len(_other_models(scene, options)) * other + 1


def _other_models(scene, options: RunOptions) -> list[str]:
    primary = options.lighting_model or scene.render.lighting_model
    return [m for m in options.compare_models if m != primary]


def write_calibration(path: Path, calibration, truth) -> dict:
    """Write a calibration file, its HTML report and (verification only) its errors against the hidden truth.

    Args:
        path: the calibration file; ``calibration_report.html`` and ``calibration_errors.json`` go beside it.
        calibration: :class:`lftransfer.calibration.rig.Calibration`.
        truth: the simulated rig's true ``RigModel``.

    Returns:
        The errors (:func:`lftransfer.verify.calibration_errors`).
    """
    from lftransfer.calibration.report import write_calibration_report

    calibration.write(path)
    errors = calibration_errors(calibration, truth)
    write_json(path.parent / "calibration_errors.json", errors)
    write_calibration_report(path.parent / "calibration_report.html", calibration, errors)
    return errors


def run_scene(scene, out: str | Path, options: RunOptions = RunOptions(), *,
              progress: Progress | None = None) -> dict:
    """Run light field transfer on a scene with the simulated rig and write every output into ``out``.

    Args:
        scene: ``lftransfer.scenes.SceneConfig``.
        out: output folder (created).
        options: see :class:`RunOptions`.
        progress: called with a description and the number of steps done.

    Returns:
        The report (also written as ``report.json``).
    """
    done = [0]

    def step(msg: str) -> None:
        done[0] += 1
        if progress:
            progress(msg, done[0])

    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    step("set up the simulated rig")
    if options.rig_model not in RIG_MODELS:
        raise ValueError(f"rig_model must be one of {RIG_MODELS}, got {options.rig_model!r}")
    seed = options.truth_seed
    # The world as it is (hidden from the pipeline): the rig as built and the point light where it stands.
    real_scene, truth = hidden_world(scene, seed)
    rig = SimRig(real_scene, truth=truth, capture_spp=options.capture_spp)
    timings["setup"] = time.perf_counter() - t0
    calibration, calibration_errors_ = None, None
    if options.calibration is not None:
        calibration = load_calibration(options.calibration, scene)
        model, rig_model = calibration.model, f"calibration file {options.calibration}"
    elif options.rig_model == "calibrated":
        t = time.perf_counter()
        calibration = calibrate_rig(rig, scene, progress=step)
        timings["calibration"] = time.perf_counter() - t
        model, rig_model = calibration.model, "calibrated"
    elif options.rig_model == "oracle":
        model, rig_model = rig.truth, "true (oracle)"
    else:
        model, rig_model = nominal_rig(scene.rig), "nominal (rig file)"
    if calibration is not None:
        step("calibration report")
        calibration_errors_ = write_calibration(Path(out) / "calibration.json", calibration, rig.truth)
    primary = options.lighting_model or scene.render.lighting_model
    render = scene.render
    settings = TransferSettings(bounces=options.bounces, angular_samples=scene.rig.angular_samples,
                                lighting_model=primary, aperture_samples=render.aperture_samples,
                                lf_spp=render.spp, view_spp=render.spp, renderer=options.renderer)
    result = run_transfer(rig, model, scene, settings, progress=step)
    for k, v in result.timings_s.items():
        timings[k] = timings.get(k, 0.0) + v

    t = time.perf_counter()
    gt = render_ground_truth(real_scene, spp=options.gt_spp or render.gt_spp, use_cache=options.use_cache,
                             progress=step)
    timings["ground_truth"] = time.perf_counter() - t
    metrics = evaluate(result, gt)
    by_model = {primary: {k: metrics[k] for k in ("cross_transfer_rel_error", "psnr_db")}}
    for other in _other_models(scene, options):
        t = time.perf_counter()
        alt = run_transfer(rig, model, scene, replace(settings, lighting_model=other, bounce_views=False),
                           progress=step)
        m = evaluate(alt, gt)
        by_model[other] = {k: m[k] for k in ("cross_transfer_rel_error", "psnr_db")}
        timings[f"transfer_{other}_model"] = time.perf_counter() - t

    comp = composite(result.synthetic_view.rgb, result.synthetic_view.alpha, result.real_view)
    timings["total"] = time.perf_counter() - t0
    from lftransfer.backend import variant

    report = {
        **{k: metrics[k] for k in ("psnr_db", "psnr_db_direct_only", "cross_transfer_rel_error",
                                   "gt_noise_psnr_db", "cross_gt_noise_rel")},
        "lighting_model": primary,
        "by_lighting_model": by_model,
        "cross_term_rel_size": metrics["cross_term_rel_size"],
        "bounces": [{"index": b.index, "real_energy": b.real_energy, "synthetic_energy": b.synthetic_energy,
                     "projector_gain": b.projector_gain} for b in result.bounces],
        "projector_clipped_fraction": result.clipped_fraction,
        "timings_s": {k: round(v, 3) for k, v in timings.items()},
        "resolution": {
            "lenslets": [scene.rig.rows, scene.rig.cols], "lattice": scene.rig.lattice,
            "lf_camera": list(scene.rig.lf_camera), "projector": list(scene.rig.projector),
            "view": list(scene.view.resolution), "angular_samples": scene.rig.angular_samples,
            "metrics": metrics["metric_resolution"],
        },
        "gt_spp": options.gt_spp or render.gt_spp,
        "renderer": resolve_renderer(scene, options.renderer),
        "truth_seed": options.truth_seed,
        "rig_model": rig_model,
        "calibration_errors": calibration_errors_,
        "variant": variant(),
        "scene": str(scene.source) if scene.source else None,
    }
    step("write outputs")
    write_outputs(out, result, gt.image, comp, report, captured_raw=result.captured_raw,
                  camera_bits=scene.rig.lf_camera_bits)
    return report
