"""One complete run on a chosen rig: calibration, transfer, (where the rig has an oracle) ground truth and
metrics, and every output file.

This is what ``lft run``, ``lft demo`` and ``lft record`` call. The rig is picked by a rig spec
(:mod:`lftransfer.runs.rigs`); the settings are resolved once from the scene and the options
(:func:`lftransfer.settings.resolve_settings`). The pipeline itself (:func:`lftransfer.calibration.rig.calibrate_rig`,
:func:`lftransfer.transfer.run_transfer`) gets the rig and the synthetic part of the scene only; verification
against ground truth goes through the rig's oracle (:mod:`lftransfer.sim.oracle`). A run is a sequence of named
stages (:func:`run_scene`); it reports progress through a callback and never prints.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from lftransfer import choices
from lftransfer.runs.cluster import ClusterSpec
from lftransfer.reports.report import emitter_ceiling, write_outputs
from lftransfer.runs.rigs import (NOMINAL, CalibrationFailedError, Knowledge, OpenedRig, RigSpec, calibrate,
                                 know_rig, knowledge, open_rig, will_calibrate, write_calibration)
from lftransfer.runs.run_folder import VIEWS_FILE, clear_run_folder, tracked_run, write_status, write_views
from lftransfer.calibration.interfaces import count_steps as count_calibration_steps
from lftransfer.rig.model import nominal_rig
from lftransfer.settings import Overrides, RunSettings, resolve_settings
from lftransfer.transfer.bounce import count_steps, run_transfer
from lftransfer.transfer.interfaces import run_interfaces
from lftransfer.render.selection import approximations, visible_steps
from lftransfer.reports.verdict import verdict

if TYPE_CHECKING:
    from lftransfer.sim.metrics import NegativeControl

__all__ = ["BY_MODEL_KEYS", "CalibrationFailedError", "RigSpec", "RunOptions", "VIEWS_FILE", "calibrate",
           "count_run_steps", "floor_skipped", "gt_steps", "knowledge", "negative_control_skipped", "open_rig",
           "run_scene", "write_calibration", "write_views"]

Progress = Callable[[str, int], None]   # (description, steps done so far)
Operator = Callable[[str], None]        # shows an instruction to the person at the rig and waits
Warn = Callable[[str], None]            # shows one line of warning


@dataclass(frozen=True)
class RunOptions:
    """Options of a run.

    Attributes:
        settings: what the run overrides of the scene's settings and what it measures beside them
            (:class:`lftransfer.settings.Overrides`; resolved once by :meth:`resolve`).
        capture_spp: rays per LF camera pixel in the simulated rig.
        use_cache: cache ground-truth renders.
        truth_seed: None: the simulated rig is built exactly as the rig file says; a seed: it is built with
            deviations drawn from that seed (:func:`lftransfer.sim.truth.perturbed_rig`), and its point light
            stands away from the file's position (:func:`lftransfer.sim.truth.true_light_scene`).
        rig_model: what the pipeline knows of the rig (:data:`lftransfer.choices.RigModel`): ``"calibrated"``
            (run every calibration step through the rig first), ``"nominal"`` (the rig file's values,
            uncalibrated) or ``"oracle"`` (the simulated rig's hidden truth, the point light where it really
            stands: a verification baseline, what perfect calibration would reach). A calibration puts the
            synthetic side's point light where it measured the real one (the scene file's position where it has
            none).
        calibration: a calibration file to use instead of calibrating (``rig_model`` is then ignored).
        recalibrate: calibrate through the simulated rig even where the calibration cache holds this rig's
            calibration (:mod:`lftransfer.runs.calibration_cache`), and store the new one.
        time_s: the moment of an animated scene the run renders (None: t = 0; the run says which, in a warning).
        rig: which rig (:class:`~lftransfer.runs.rigs.RigSpec`); ``truth_seed``, ``capture_spp`` and the
            ``oracle`` model are for the simulated rig only. A replay of a recording made on the simulated rig is
            verified against the same hidden truth (the recording's manifest names its truth seed).
        record: a folder to record every rig request and answer into (:class:`lftransfer.rig.replay.RecordingRig`).
        verify: compare with the path-traced ground truth where the rig has an oracle.
        negative_control: also run the transfer with the rig file's nominal values on the same rig (no
            calibration, the same ground truth) and report how much worse it scores (the report's
            ``negative_control``; :func:`negative_control_skipped` says when it cannot run). ``lft demo`` sets it.
        floor: on the simulated rig, verified: find the fidelity floor (:mod:`lftransfer.sim.floor`: the best any
            algorithm could do through this rig, each side) and report the error against it.
        cluster: a Ray cluster (:class:`~lftransfer.runs.cluster.ClusterSpec`) to spread a quiet reference's rounds
            over (:mod:`lftransfer.runs.reference_pool`); None: this process.
    """

    settings: Overrides = Overrides()
    capture_spp: int = choices.DEFAULT_CAPTURE_SPP
    use_cache: bool = True
    truth_seed: int | None = 0
    rig_model: choices.RigModel = choices.DEFAULT_RIG_MODEL
    calibration: Path | None = None
    recalibrate: bool = False
    time_s: float | None = None
    rig: RigSpec = RigSpec()
    record: Path | None = None
    verify: bool = True
    negative_control: bool = False
    floor: bool = True
    cluster: ClusterSpec | None = None

    def __post_init__(self) -> None:
        problems = []
        if not isinstance(self.settings, Overrides):
            problems.append(f"settings must be an Overrides, got {type(self.settings).__name__}")
        if not (isinstance(self.capture_spp, int) and self.capture_spp >= 1):
            problems.append(f"capture_spp must be an integer >= 1, got {self.capture_spp!r}")
        if self.truth_seed is not None and not (isinstance(self.truth_seed, int) and self.truth_seed >= 0):
            problems.append(f"truth_seed must be an integer >= 0 (or None), got {self.truth_seed!r}")
        try:
            choices.check_choice("rig_model", self.rig_model, choices.RigModel)
        except ValueError as exc:
            problems.append(str(exc))
        if self.cluster is not None and not self.settings.quiet_reference:
            problems.append("cluster spreads a quiet reference's rounds: ask for one (quiet_reference, "
                            "--quiet-reference)")
        if problems:
            raise ValueError("; ".join(problems))

    def resolve(self, scene, *, live: bool = False, loop: str | None = None, **transfer_changes) -> RunSettings:
        """The settings this run uses on ``scene`` (:func:`lftransfer.settings.resolve_settings`; ``live``,
        ``loop`` and ``transfer_changes`` as it takes them)."""
        return resolve_settings(scene, self.settings, live=live, loop=loop, **transfer_changes)


def _calibrates(options: RunOptions) -> bool:
    return options.calibration is None and options.rig_model == "calibrated"


def _verifies(options: RunOptions) -> bool:
    """Whether the run will have an oracle to verify against: the simulated rig, or a recording made on it (its
    manifest names the truth seed; :func:`lftransfer.sim.oracle.oracle_of_recording`)."""
    if not options.verify:
        return False
    if options.rig.kind == "replay":
        import json

        try:
            meta = json.loads((Path(options.rig.path) / "manifest.json").read_text(encoding="utf-8")).get("meta") or {}
        except (OSError, ValueError, AttributeError):
            return False
        return meta.get("rig") == "sim" and "truth_seed" in meta
    return options.rig.kind == "sim"


def negative_control_skipped(options: RunOptions, bounces: int) -> str | None:
    """Why the negative control of a run that asks for it (``options.negative_control``) cannot tell anything,
    or None when it runs: it needs the simulated rig with a hidden truth, verification, a run that knows more
    than the nominal model, and at least one bounce (``bounces``, the run's resolved N)."""
    if options.rig.kind != "sim":
        return (f"the negative control runs on the simulated rig only (this run's rig: {options.rig.kind}), where "
                f"the ground truth is known")
    if not options.verify:
        return "the run is not verified against ground truth"
    if options.truth_seed is None:
        return ("the simulated rig is built exactly as its file says (--exact-rig), so the nominal model is its "
                "truth, not an uncalibrated model")
    if options.calibration is None and options.rig_model == "nominal":
        return "the run itself uses the nominal rig model (--rig-model nominal)"
    if bounces == 0:
        return "with 0 bounces no light field crosses the array, so the rig model changes nothing the metrics see"
    return None


def floor_skipped(options: RunOptions) -> str | None:
    """Why a run finds no fidelity floor (:mod:`lftransfer.sim.floor`), or None when it does: it needs the
    simulated rig itself (its renderer and truth) and verification."""
    if not options.floor:
        return "not asked for (--no-floor)"
    if options.rig.kind != "sim":
        return (f"the fidelity floor is found on the simulated rig only (this run's rig: {options.rig.kind}), with "
                f"its truth")
    if not options.verify:
        return "the run is not verified against ground truth"
    return None


FLOOR_STEPS = 2                 # progress steps of the fidelity floor: the synthetic side, the real side


def _runs_control(options: RunOptions, settings: RunSettings) -> bool:
    return options.negative_control and negative_control_skipped(options, settings.bounces) is None


def _at_moment(scene, options: RunOptions):
    """The scene a run runs: an animated one posed at ``options.time_s`` (0 unless given), a still one as it is."""
    return scene.at(float(options.time_s or 0.0)) if scene.moving else scene


def count_run_steps(scene, options: RunOptions) -> int:
    """Progress steps of :func:`run_scene`, for a progress bar: set-up, calibration and its report, the transfer,
    6 ground-truth renders (where verified), each comparison re-run and the negative control with its own
    settings, writing. Counted from the same resolved settings the run uses."""
    scene = _at_moment(scene, options)                   # the moment run_scene runs
    settings = options.resolve(scene)
    calibration = (count_calibration_steps(scene) if will_calibrate(scene, options) else 0) \
        + (1 if _calibrates(options) or options.calibration is not None else 0)
    reruns = sum(count_steps(settings.rerun(name, value)) for name, value in settings.comparisons)
    control = count_steps(replace(settings.transfer, bounce_views=False)) if _runs_control(options, settings) else 0
    floor = FLOOR_STEPS if floor_skipped(options) is None else 0
    if scene.interfaces:           # several interfaces: their loop, and the first one alone as the control
        from lftransfer.transfer.interfaces import count_interface_steps

        n = len(scene.interfaces)
        control = count_interface_steps(replace(settings.transfer, bounce_views=False), 1) if _verifies(options) else 0
        return (1 + calibration + count_interface_steps(settings.transfer, n)
                + (gt_steps(settings) if _verifies(options) else 0) + floor + control + 1)
    # each ablation: the transfer without its bounce views, given a depth (no step to measure it)
    ablations = 2 * (count_steps(replace(settings.transfer, bounce_views=False)) - 1) \
        if _runs_ablations(options, settings) else 0
    return (1 + calibration + count_steps(settings.transfer) + (gt_steps(settings) if _verifies(options) else 0)
            + floor + reruns + ablations + control + 1)


SURFACE_SHIFT_M = 0.02          # the solve's negative control: the measured depth moved this far


def _runs_ablations(options: RunOptions, settings: RunSettings) -> bool:
    """Whether a run measures its solve's ablations (:meth:`_Run.surface_ablations`): a verified run with
    comparisons (the demo's) whose projection is the surface solve."""
    return bool(settings.comparisons) and settings.transfer.projection == "solve" and \
        settings.transfer.prefilters and _verifies(options)


def gt_steps(settings: RunSettings) -> int:
    """Progress steps of a run's ground truth: its 6 renders, or a quiet reference's rounds at most."""
    from lftransfer.sim.reference import MAX_ROUNDS

    return 1 + MAX_ROUNDS if settings.quiet_reference else 6


def run_scene(scene, out: str | Path, options: RunOptions = RunOptions(), *,
              progress: Progress | None = None, operator: Operator | None = None,
              warn: Warn | None = None) -> dict:
    """Run light field transfer on a scene with the chosen rig and write every output into ``out``.

    ``out/status.json`` says whether the run is ``running``, ``complete``, ``failed`` or ``interrupted``
    (:mod:`lftransfer.runs.run_folder`); an earlier run's outputs in ``out`` are removed first, so the folder
    never mixes two runs, and no temporary file stays. Every file is written atomically, so what a failed run
    wrote before its failure stays readable.

    Args:
        scene: ``lftransfer.scenes.SceneConfig`` (a simulated rig takes its real objects as its hidden world; the
            pipeline gets ``scene.synthetic_part()`` only).
        out: output folder (created).
        options: see :class:`RunOptions`.
        progress: called with a description and the number of steps done (:func:`count_run_steps` in all).
        operator: shows an instruction to the person at a physical rig and waits.
        warn: called with one line for each warning (also listed in the report's ``warnings``): a bad
            ground-truth cache entry, a ground truth too noisy for the error it measures.

    Returns:
        The report (also written as ``report.json``).
    """
    out = Path(out)
    write_status(out, "running", rig=str(options.rig))
    clear_run_folder(out, keep=[options.calibration] if options.calibration is not None else [])
    moment = None
    if scene.moving:                     # one moment of an animated scene, said in the terminal and the report
        moment = (f"the scene is animated ({scene.frame_times()[-1]:g} s): this run renders its moment t = "
                  f"{float(options.time_s or 0.0):g} s (--time for another; lft render renders the animation)")
    scene = _at_moment(scene, options)
    with tracked_run(out, str(options.rig)):
        opened = None
        try:
            opened = open_rig(scene, options, operator=operator, interfaces=True)
            run = _Run(scene, out, options, opened, progress, warn)
            if moment is not None:
                run.warning(moment)
            report = run.run()
        finally:
            if opened is not None:
                opened.close()
    return report


SATURATION_WARNING = 0.01       # warn when more of the direct capture's LF camera codes than this are at full scale
BY_MODEL_KEYS = ("cross_transfer_rel_error", "psnr_db", "psnr_objects_db")   # per lighting model and reconstruction
METRIC_KEYS = ("psnr_db", "psnr_db_direct_only", "psnr_objects_db", "psnr_objects_db_direct_only",
               "cross_transfer_rel_error", "gt_noise_psnr_db", "cross_gt_noise_rel")
TABLES = {"lighting_model": "by_lighting_model", "reconstruction": "by_reconstruction",
          "projection": "by_projection", "window": "by_window"}


@dataclass(frozen=True)
class ControlRun:
    """A negative control that ran.

    Attributes:
        result: its metrics set against the run's (:class:`lftransfer.sim.metrics.NegativeControl`).
        seconds: wall time of the control's transfer and evaluation, s.
    """

    result: NegativeControl
    seconds: float


@dataclass
class _Run:
    """One run's stages, in order (:meth:`run`): know the rig, transfer, verify, compare, control, report.

    Each stage is a method that reads what the earlier ones left on the object; progress steps, warnings and
    wall times are gathered here."""

    scene: object
    out: Path
    options: RunOptions
    opened: OpenedRig
    progress: Progress | None
    warn: Warn | None
    settings: RunSettings = None
    done: int = 0
    warnings: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    undefined: dict = field(default_factory=dict)
    reference: object = None          # what a quiet reference reached (sim.reference.Reference)
    known: object = None              # what the run knows of its rig (runs.rigs.Knowledge), once known
    interfaces_effect: dict | None = None   # several interfaces: the light added to the [effect]'s object

    def step(self, msg: str) -> None:
        self.done += 1
        if self.progress:
            self.progress(msg, self.done)

    def warning(self, msg: str) -> None:
        self.warnings.append(msg)
        if self.warn:
            self.warn(msg)

    def run(self) -> dict:
        t0 = self.started = time.perf_counter()
        self.step(f"set up the rig ({self.options.rig})")
        if self.options.rig_model == "oracle" and self.opened.oracle is None:
            raise ValueError("--rig-model oracle needs the simulated rig's truth (--rig sim)")
        self.settings = self.options.resolve(self.scene)
        self.timings["setup"] = time.perf_counter() - t0
        known, label, errors = self.know_rig()
        self.known = known
        result = self.transfer(known)
        gt, metrics, tables, gt_spp_needed = self.verify(result)
        floor = self.floor(result, gt)
        self.compare(known, gt, tables, result)
        ablations = self.surface_ablations(known, result, gt)
        control = self.negative_control(result, gt)
        self.timings["total"] = time.perf_counter() - t0
        report = self.report(known, label, errors, result, metrics, tables, control, gt_spp_needed, floor, gt)
        report["occlusion"] = self.occlusion(result, gt)
        report["surface_ablations"] = ablations
        if self.opened.rigs:
            from lftransfer.runs.interfaces import interfaces_report

            report["interfaces"] = interfaces_report(self.scene, result, self.interfaces_effect)
        report = {"verdict": verdict(report), **report}           # first: what a reader looks for first
        self.step("write outputs")
        comp = result.composite()
        from lftransfer.sim.metrics import cross_term_image

        cross_truth = None if gt is None else cross_term_image(gt)
        write_outputs(self.out, result, gt.image if gt is not None else None, comp, report,
                      captured_raw=result.captured_raw, camera_bits=self.scene.rig.lf_camera_bits,
                      ceiling=emitter_ceiling(known.scene), cross_truth=cross_truth)
        return report

    def know_rig(self) -> tuple[Knowledge, str, dict | None]:
        """Stage 1: what the pipeline knows of the rig (a calibration file, the calibration cache, calibrated now,
        nominal or the oracle; :func:`~lftransfer.runs.rigs.know_rig`), the calibration written with its report
        and (with an oracle) its errors."""
        t = time.perf_counter()
        known, errors, calibrated_now = know_rig(self.opened, self.scene, self.options, self.out / "calibration.json",
                                                 progress=self.step)
        for note in known.warnings:
            self.warning(note)
        if calibrated_now:
            self.timings["calibration"] = time.perf_counter() - t
        return known, known.rig_model, errors

    def transfer(self, known: Knowledge):
        """Stage 2: the transfer with the run's settings."""
        for note in visible_steps(known.scene, self.settings.transfer.renderer):
            self.warning(note)
        if self.opened.rigs:            # several interfaces: the exchange through all of them
            result = run_interfaces(self.opened.rigs, known.models, known.scene, self.settings.transfer,
                                    progress=self.step)
        else:
            result = run_transfer(self.opened.rig, known.model, known.scene, self.settings.transfer,
                                  progress=self.step)
        for k, v in result.timings_s.items():
            self.timings[k] = self.timings.get(k, 0.0) + v
        if result.saturated_fraction > SATURATION_WARNING:
            self.warning(f"{100 * result.saturated_fraction:.2g} % of the LF camera's codes are at full scale in the "
                         f"direct capture: the light clipped there does not reach the synthetic side (lower [rig] "
                         f"exposure, or the lights' intensity)")
        if not self.verified:                 # what a later scoring against a truth needs (lft twin score)
            write_views(self.out / VIEWS_FILE, result)
        stale = self.opened.stale_captures            # a hardware rig's (None for others)
        if stale:
            self.warning(f"{stale} capture(s) saw frames that still changed after the rig file's settle_s: they were "
                         "dropped, not averaged, and the captures waited; settle_s is too short (lft calibrate "
                         "latency)")
        return result

    @property
    def verified(self) -> bool:
        return self.options.verify and self.opened.oracle is not None

    def verify(self, result):
        """Stage 3: the ground truth (through the oracle) and the run's metrics against it; the comparison tables
        start with the run's own row."""
        s = self.settings.transfer
        tables = {"by_lighting_model": {s.lighting_model: {}}, "by_reconstruction": {s.reconstruction: {}},
                  "by_projection": {s.projection: {}}, "by_window": {s.window: {}}}
        if not self.verified:
            return None, None, tables, None
        from lftransfer.sim.metrics import evaluate, gt_noise_verdict

        t = time.perf_counter()
        if self.settings.quiet_reference:
            gt = self.quiet_ground_truth(result)
        else:
            gt = self.opened.oracle.ground_truth(spp=self.settings.gt_spp, use_cache=self.options.use_cache,
                                                 progress=self.step, warn=self.warning)
        self.timings["ground_truth"] = time.perf_counter() - t
        metrics = evaluate(result, gt)
        row = {k: getattr(metrics, k) for k in BY_MODEL_KEYS}
        for table in tables.values():
            table[next(iter(table))] = row
        noisy = gt_noise_verdict(metrics, self.reference.spp if self.reference is not None else self.settings.gt_spp)
        gt_spp_needed = None
        if noisy is not None:
            self.warning(noisy.message())
            gt_spp_needed = noisy.spp_needed
        return gt, metrics, tables, gt_spp_needed

    def quiet_ground_truth(self, result):
        """The ground truth rendered until its noise on the cross term is at most a third of the run's error
        (:mod:`lftransfer.sim.reference`); what it reached goes to the report's ``reference``."""
        from lftransfer.runs.reference_pool import reference_renderer
        from lftransfer.sim.metrics import composites, metric_factor
        from lftransfer.sim.reference import MAX_ROUNDS, cross_term_judge

        comp_n, comp_0 = composites(result)
        judge = cross_term_judge(comp_n, comp_0)
        with reference_renderer(self.options.cluster, use_cache=self.options.use_cache, step=self.step) as (
                render, parts):
            gt, self.reference = self.opened.oracle.quiet_ground_truth(
                judge, spp=self.settings.gt_spp, multiple=metric_factor(comp_n.shape[1]),
                use_cache=self.options.use_cache, parts=parts, render=render, progress=self.step, warn=self.warning,
                budget_s=self.settings.reference_budget_s or time.perf_counter() - self.started)
        for _ in range(1 + MAX_ROUNDS - self.reference.rounds):
            self.step("ground truth: quiet enough")
        ref = self.reference
        if not ref.met and ref.ratio is not None:
            why = {"budget": f"its budget of {ref.budget_s:.0f} s (--reference-budget raises it)",
                   "samples": "its most samples", "rounds": "its most rounds"}.get(ref.stopped, ref.stopped)
            self.warning(f"the quiet reference stopped at {ref.spp} samples per pixel, {why}, with its noise on the "
                         f"cross term at {ref.ratio:.2g} of the error (target {ref.target:.2g})")
        return gt

    def floor(self, result, gt):
        """Stage 3b: the fidelity floor (through the oracle), where the run can find one; else its reason in
        ``undefined``."""
        why = floor_skipped(self.options)
        if why is None and gt is None:
            why = "the run is not verified against ground truth"
        if why is not None:
            self.undefined["fidelity_floor"] = why
            return None
        t = time.perf_counter()
        rig = list(self.opened.rigs) or getattr(self.opened.rig, "inner", self.opened.rig)
        floor = self.opened.oracle.fidelity_floor(rig, result, gt, self.settings.transfer, progress=self.step)
        self.timings["fidelity_floor"] = time.perf_counter() - t
        return floor

    def compare(self, known: Knowledge, gt, tables: dict, result) -> None:
        """Stage 4: the same run with one setting changed, for each comparison the settings ask for, measured (with
        the run's own measurement of the real scene's depth for the depth composite, which takes 24 photographs of
        structured light: the same rig, model and scene)."""
        reuse = {"depth": result.depth, "view_depth": result.view_depth} if result.view_depth is not None else {}
        if self.opened.rigs and self.settings.comparisons:
            self.warning("the comparisons of settings run through one interface: not run on this scene's "
                         f"{len(self.opened.rigs)}")
            return
        for name, value in self.settings.comparisons:
            t = time.perf_counter()
            alt = run_transfer(self.opened.rig, known.model, known.scene, self.settings.rerun(name, value),
                               progress=self.step, **reuse)
            if gt is not None:
                from lftransfer.sim.metrics import evaluate

                m = evaluate(alt, gt)
                tables[TABLES[name]][value] = {k: getattr(m, k) for k in BY_MODEL_KEYS}
            self.timings[f"transfer_{value}_{'model' if name == 'lighting_model' else name}"] = \
                time.perf_counter() - t

    def surface_ablations(self, known: Knowledge, result, gt) -> dict | None:
        """Stage 4b (the surface solve, where the run compares): the same transfer given the oracle's true depth
        (what the solve reaches with a perfect measurement: the rest is the method's) and given the measured depth
        moved :data:`SURFACE_SHIFT_M` farther (a negative control: it must do worse). Each: the cross-transfer error
        and the real side scored as the fidelity floor scores it."""
        if not _runs_ablations(self.options, self.settings) or gt is None or result.depth is None or self.opened.rigs:
            return None
        import numpy as np

        from lftransfer.sim.metrics import evaluate

        oracle, s = self.opened.oracle, replace(self.settings.transfer, bounce_views=False)
        U = s.angular_samples

        def scored(res) -> dict:
            real, synthetic = oracle.score_cross(gt, res.composite() - res.composite_direct())
            return {"cross_transfer_rel_error": evaluate(res, gt).cross_transfer_rel_error, "real_side": real,
                    "synthetic_side": synthetic}

        out = {"run": scored(result)}
        for name, depth in (("oracle_surface", oracle.lightfield_depth(known.model, U, U)),
                            ("depth_moved_2cm", np.asarray(result.depth) + SURFACE_SHIFT_M)):
            t = time.perf_counter()
            alt = run_transfer(self.opened.rig, known.model, known.scene, s, progress=self.step, depth=depth,
                               view_depth=result.view_depth)
            out[name] = scored(alt)
            self.timings[f"solve_{name}"] = time.perf_counter() - t
        known_depth = np.isfinite(np.asarray(result.depth))
        truth = out["oracle_surface"]
        out["notes"] = [
            "oracle_surface: the same solve given the real objects' true depth along the model's entries (no "
            "measurement error): its gap to the floor is the method's, the run's gap beyond it the depth's",
            f"depth_moved_2cm: the measured depth moved {SURFACE_SHIFT_M * 100:.0f} cm away from the array "
            "(a negative control: the light is aimed where the surface is not)",
            f"real_side: the real side's cross term scored as the fidelity floor scores it (noise-corrected); the "
            f"measured depth knew {known_depth.mean():.0%} of the entries"]
        if truth["real_side"] is not None and out["run"]["real_side"] is not None:
            out["depth_share"] = out["run"]["real_side"] - truth["real_side"]
        return out

    def negative_control(self, result, gt) -> ControlRun | None:
        """Stage 5: the run again with the rig file's nominal values on the same rig, set against the run's result
        on the same ground truth (:func:`lftransfer.sim.metrics.negative_control`), where it can tell anything. With
        several interfaces, always (where verified): the run through the first interface alone, which must be
        measurably worse (what the others carry)."""
        if self.opened.rigs and self.verified:
            return self._first_interface_only(result, gt)
        if not self.options.negative_control:
            self.undefined["negative_control"] = ("not asked for: lft demo runs it (the rig file's nominal values on "
                                                  "the same rig, against the same ground truth)")
            return None
        why = negative_control_skipped(self.options, self.settings.bounces) or \
            (None if self.verified else "the run is not verified against ground truth")
        if why is not None:
            self.undefined["negative_control"] = why
            return None
        from lftransfer.sim.metrics import negative_control

        t = time.perf_counter()
        alt = run_transfer(self.opened.rig, nominal_rig(self.scene.rig), self.scene.synthetic_part(),
                           replace(self.settings.transfer, bounce_views=False),
                           progress=lambda msg: self.step(f"negative control: {msg}"))
        control = ControlRun(result=negative_control(result, alt, gt, NOMINAL), seconds=time.perf_counter() - t)
        self.timings["negative_control"] = control.seconds
        if not control.result.measurably_worse:
            self.warning(control.result.message())
        return control

    def _first_interface_only(self, result, gt) -> ControlRun:
        from lftransfer.runs.interfaces import through_first_alone

        t = time.perf_counter()
        control, self.interfaces_effect = through_first_alone(self.opened, self.known, self.scene, self.settings,
                                                              result, gt, self.step)
        control = ControlRun(result=control, seconds=time.perf_counter() - t)
        self.timings["first_interface_only"] = control.seconds
        if not control.result.measurably_worse:
            self.warning(control.result.message())
        return control

    def occlusion(self, result, gt) -> dict | None:
        """Where a real object hides a synthetic one: the over and the depth-aware composites of this run scored
        there (:func:`lftransfer.sim.metrics.occlusion_metrics`); None unverified or where nothing is hidden."""
        if gt is None:
            return None
        from lftransfer.sim.metrics import occlusion_metrics

        return occlusion_metrics(result, gt)

    def direct_light(self, known, result) -> dict:
        """What lit the synthetic objects directly: ``kind`` ("point" or "probe", the settings' ``direct_light``);
        on a light probe scene the probe's measurement (:meth:`ProbeMeasurement.summary`), the point light that
        stood in for it where ``kind`` is "point", and (verified runs) the map's errors against the true room."""
        s = self.settings.transfer
        out: dict = {"kind": s.direct_light}
        if result.probe is None:
            return out
        out["probe"] = result.probe.summary()
        if s.direct_light == "probe":
            out["steep_room_light"] = ("the room behind the synthetic objects projected stronger for the steep room "
                                       "light the array's panel shades on the real side, as irradiance on surfaces "
                                       "facing the array (transfer/room.py)" if s.prefilters else
                                       "not sent: it needs a measured depth (projection \"depth\" or \"solve\")")
        if s.direct_light == "point":
            from lftransfer.scenes.frame import scene_in_frame
            from lftransfer.transfer.synthetic_side import probe_point_light

            posed = scene_in_frame(known.scene, known.model.world_to_array())
            light = probe_point_light(result.probe.radiance, posed)
            out["point_light"] = {"position": [round(float(v), 4) for v in light.position],
                                  "intensity": [round(float(v), 4) for v in light.intensity]}
        if self.verified:
            errors = self.opened.oracle.probe_errors(result.probe, known.model.world_to_array())
            if errors is not None:
                out["probe"]["against_truth"] = errors
        return out

    def real_depth(self, result, gt=None) -> dict | None:
        """What the depth composite knew of the real scene's depth in the view camera: its source and the pixels
        it covers, and (verified runs) its error against the true depth (:func:`lftransfer.sim.metrics.depth_errors`:
        the ground truth's own, where it rendered one); None with the over composite."""
        vd = result.view_depth
        if vd is None:
            return None
        from lftransfer.real_depth.fusion import share_taken

        out = {"source": vd.source, "known_fraction": float(vd.known.mean())}
        truth = None
        if self.verified:
            from lftransfer.sim.metrics import depth_errors

            truth = gt.depth_real if gt is not None and gt.depth_real is not None else \
                self.opened.oracle.real_view_depth()
            out.update(depth_errors(vd, truth))
        if len(result.depth_sources) > 1:                 # each source alone, and where the fused map took it
            out["sources"] = {}
            outlined = any(d.source == "outline" for d in result.depth_sources)
            for d in result.depth_sources:
                entry = {"known_fraction": float(d.known.mean())}
                if not (outlined and d.source == "lightfield"):     # the outline's replaces it, it is not fused
                    entry["chosen_fraction"] = share_taken(vd, d)
                if truth is not None:
                    entry.update(depth_errors(d, truth))
                out["sources"][d.source] = entry
        return out

    def report(self, known: Knowledge, label: str, errors, result, metrics, tables: dict,
               control: ControlRun | None, gt_spp_needed, floor=None, gt=None) -> dict:
        """Stage 6: the report (``report.json``): metrics, comparisons, settings, energies, timings, provenance."""
        from lftransfer.backend import variant

        scene, options, s = self.scene, self.options, self.settings.transfer
        measured = metrics.to_json() if metrics is not None else {}
        undefined = {**measured.get("undefined", {}), **self.undefined}
        return {
            **{k: measured.get(k) for k in METRIC_KEYS},
            "verification": "against path-traced ground truth" if self.verified else
            f"none: the {options.rig.kind} rig's real scene is not known to lftransfer",
            "lighting_model": s.lighting_model,
            "by_lighting_model": tables["by_lighting_model"],
            "reconstruction": s.reconstruction,
            "projection": s.projection,
            "by_reconstruction": tables["by_reconstruction"],
            "by_projection": tables["by_projection"],
            "window": s.window,
            "by_window": tables["by_window"],
            "composite": s.composite,
            "real_depth": self.real_depth(result, gt),
            "direct_light": self.direct_light(known, result),
            "negative_control": control.result.to_json() if control is not None else None,
            "real_floor": floor.real_floor if floor is not None else None,
            "synthetic_floor": floor.synthetic_floor if floor is not None else None,
            "transfer_over_floor": floor.transfer_over_floor if floor is not None else None,
            "fidelity_floor": floor.to_json() if floor is not None else None,
            "reference": self.reference.to_json() if self.reference is not None else None,
            "undefined_metrics": undefined,
            "warnings": self.warnings,
            "gt_spp_needed": gt_spp_needed,
            "cross_term_rel_size": measured.get("cross_term_rel_size"),
            "cross_by_side": measured.get("cross_by_side"),
            "psnr_by_side": measured.get("psnr_by_side"),
            "bounces": [{"index": b.index, "real_energy": b.real_energy, "synthetic_energy": b.synthetic_energy,
                         "projector_gain": b.projector_gain} for b in result.bounces],
            "projector_clipped_fraction": result.clipped_fraction,
            "lf_camera_saturated_fraction": result.saturated_fraction,
            "timings_s": {k: round(v, 3) for k, v in self.timings.items()},
            "resolution": {
                "lenslets": [scene.rig.rows, scene.rig.cols], "lattice": scene.rig.lattice,
                "lf_camera": list(scene.rig.lf_camera), "projector": list(scene.rig.projector),
                "view": list(scene.view.resolution), "angular_samples": scene.rig.angular_samples,
                "metrics": measured.get("metric_resolution"),
            },
            "gt_spp": self.settings.gt_spp if self.verified else None,
            "renderer": s.renderer,
            "approximations": approximations(known.scene, s.renderer, max_depth=s.max_depth),
            "settings": self.settings.to_json(),
            "rig": str(options.rig),
            "truth_seed": self.opened.truth_seed,
            "rig_model": label,
            "synthetic_lights": known.lights_from,
            "calibration_errors": errors,
            "variant": variant(),
            "scene": str(scene.source) if scene.source else None,
        }
