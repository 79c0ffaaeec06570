"""One complete run on a chosen rig: calibration, transfer, (on the simulated rig) ground truth and metrics, and
every output file.

This is what ``lft run``, ``lft demo`` and ``lft record`` call. The rig is picked by a *rig spec*: ``sim`` (the
digital twin, with its hidden truth), ``hardware:RIG.toml`` (a physical rig) or ``replay:DIR`` (a recording).
The pipeline itself (:func:`lftransfer.calibration.rig.calibrate_rig`, :func:`lftransfer.transfer.run_transfer`)
gets the rig and the synthetic part of the scene only; verification against ground truth happens here, on the
simulated rig's truth. It reports progress through a callback and never prints.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from lftransfer.calibration.rig import calibrate_rig, count_calibration_steps, load_calibration
from lftransfer.composite import composite
from lftransfer.app.report import emitter_ceiling, write_json, write_outputs
from lftransfer.app.run_folder import clear_run_folder, tracked_run, write_status
from lftransfer.render.lights import RECONSTRUCTIONS, WINDOWS
from lftransfer.transfer.projection import PROJECTIONS
from lftransfer.rig.base import Rig
from lftransfer.rig.model import RigModel, nominal_rig
from lftransfer.transfer.bounce import TransferSettings, count_steps, run_transfer
from lftransfer.transfer.synthetic_side import approximations, resolve_renderer

if TYPE_CHECKING:
    from lftransfer.sim.verify import NegativeControl

Progress = Callable[[str, int], None]   # (description, steps done so far)
Operator = Callable[[str], None]        # shows an instruction to the person at the rig and waits
Warn = Callable[[str], None]            # shows one line of warning


@dataclass(frozen=True)
class RigSpec:
    """Which rig a run uses: ``sim``, ``hardware:RIG.toml`` or ``replay:DIR``.

    Attributes:
        kind: "sim", "hardware" or "replay".
        path: the rig file (hardware) or the recording's folder (replay).
    """

    kind: str = "sim"
    path: Path | None = None

    @classmethod
    def parse(cls, text: str) -> "RigSpec":
        """``"sim"``, ``"hardware:RIG.toml"`` or ``"replay:DIR"`` -> RigSpec (ValueError naming what is wrong)."""
        kind, _, rest = str(text).partition(":")
        if kind == "sim" and not rest:
            return cls("sim")
        if kind in ("hardware", "replay") and rest:
            path = Path(rest).expanduser()
            if kind == "hardware" and not path.is_file():
                raise ValueError(f"--rig {text}: the rig file {path} does not exist")
            if kind == "replay" and not (path / "manifest.json").is_file():
                raise ValueError(f"--rig {text}: {path} is not a recording (no manifest.json; make one with lft record)")
            return cls(kind, path)
        raise ValueError(f"--rig {text!r}: expected 'sim', 'hardware:RIG.toml' or 'replay:DIR'")

    def __str__(self) -> str:
        return self.kind if self.path is None else f"{self.kind}:{self.path}"


RIG_MODELS = ("calibrated", "nominal", "oracle")


@dataclass(frozen=True)
class RunOptions:
    """Options of a run.

    Attributes:
        bounces: number of bounces N.
        lighting_model: the model used for the outputs ("area", "point" or "prefiltered").
        compare_models: further lighting models whose cross-transfer error is also measured (full reruns).
        reconstruction: how the captured light field is read between lenslets ("box" or "linear"; None: the
            scene's ``render.reconstruction``), for the area lighting model.
        compare_reconstructions: further reconstructions measured beside it (full reruns, area model only).
        projection: what the projector is sent, "box" or "depth" (None: the scene's ``render.projection``; area
            model only; :mod:`lftransfer.transfer.projection`).
        compare_projections: further projections measured beside it (full reruns, area model only).
        window: what the synthetic scene receives from beyond the lenslets' window, "edge" or "cut" (None: the
            scene's ``render.window``; area model only; :mod:`lftransfer.render.lights`).
        compare_windows: further windows measured beside it (full reruns, area model only).
        gt_spp: samples per pixel of each ground-truth render (None: the scene's ``render.gt_spp``).
        capture_spp: rays per LF camera pixel in the simulated rig.
        use_cache: cache ground-truth renders.
        renderer: synthetic renderer, "auto" (fast path where the scene allows), "fast" or "exact".
        truth_seed: None: the simulated rig is built exactly as the rig file says; a seed: it is built with
            deviations drawn from that seed (:func:`lftransfer.sim.truth.perturbed_rig`), and its point light
            stands away from the file's position (:func:`lftransfer.sim.truth.true_light_scene`).
        rig_model: what the pipeline knows of the rig: ``"calibrated"`` (run every calibration step through the
            rig first), ``"nominal"`` (the rig file's values, uncalibrated) or ``"oracle"`` (the simulated rig's
            hidden truth, the point light where it really stands: a verification baseline, what perfect
            calibration would reach). A calibration puts the synthetic side's point light where it measured the
            real one (the scene file's position where it has none).
        calibration: a calibration file to use instead of calibrating (``rig_model`` is then ignored).
        rig: which rig (:class:`RigSpec`); ``truth_seed``, ``capture_spp`` and the ``oracle`` model are for the
            simulated rig only. A replay of a recording made on the simulated rig is verified against the same
            hidden truth (the recording's manifest names its truth seed).
        record: a folder to record every rig request and answer into (:class:`lftransfer.rig.replay.RecordingRig`).
        verify: compare with the path-traced ground truth where the truth is known (simulated rig, or a replay
            of one).
        negative_control: also run the transfer with the rig file's nominal values on the same rig (no
            calibration, the same ground truth) and report how much worse it scores (the report's
            ``negative_control``; :func:`negative_control_skipped` says when it cannot run). ``lft demo`` sets it.
    """

    bounces: int = 2
    lighting_model: str | None = None
    compare_models: tuple[str, ...] = ("point",)
    reconstruction: str | None = None
    compare_reconstructions: tuple[str, ...] = ()
    projection: str | None = None
    compare_projections: tuple[str, ...] = ()
    window: str | None = None
    compare_windows: tuple[str, ...] = ()
    gt_spp: int | None = None
    capture_spp: int = 4
    use_cache: bool = True
    renderer: str = "auto"
    truth_seed: int | None = 0
    rig_model: str = "calibrated"
    calibration: Path | None = None
    rig: RigSpec = RigSpec()
    record: Path | None = None
    verify: bool = True
    negative_control: bool = False

    def __post_init__(self) -> None:
        problems = []
        if not (isinstance(self.bounces, int) and self.bounces >= 0):
            problems.append(f"bounces must be an integer >= 0, got {self.bounces!r}")
        if self.gt_spp is not None and not (isinstance(self.gt_spp, int) and self.gt_spp >= 1):
            problems.append(f"gt_spp must be an integer >= 1 (or None: the scene's), got {self.gt_spp!r}")
        if not (isinstance(self.capture_spp, int) and self.capture_spp >= 1):
            problems.append(f"capture_spp must be an integer >= 1, got {self.capture_spp!r}")
        if self.truth_seed is not None and not (isinstance(self.truth_seed, int) and self.truth_seed >= 0):
            problems.append(f"truth_seed must be an integer >= 0 (or None), got {self.truth_seed!r}")
        if self.rig_model not in RIG_MODELS:
            problems.append(f"rig_model must be one of {', '.join(RIG_MODELS)}, got {self.rig_model!r}")
        if self.renderer not in ("auto", "fast", "exact"):
            problems.append(f"renderer must be auto, fast or exact, got {self.renderer!r}")
        for p in (self.projection, *self.compare_projections):
            if p is not None and p not in PROJECTIONS:
                problems.append(f"projection must be one of {', '.join(PROJECTIONS)}, got {p!r}")
        for r in (self.reconstruction, *self.compare_reconstructions):
            if r is not None and r not in RECONSTRUCTIONS:
                problems.append(f"reconstruction must be one of {', '.join(RECONSTRUCTIONS)}, got {r!r}")
        for w in (self.window, *self.compare_windows):
            if w is not None and w not in WINDOWS:
                problems.append(f"window must be one of {', '.join(WINDOWS)}, got {w!r}")
        if problems:
            raise ValueError("; ".join(problems))


QUICK_FACTOR = 4
MIN_VIEW_PIXELS = 8             # the view camera's smaller side (metrics are box-downsampled images of it)
MIN_PIXELS_PER_LENSLET = 2      # LF camera and projector pixels across one lenslet's pitch


def _too_small(scene, factor: int = 1) -> list[str]:
    """What of a scene is below the sizes the pipeline works at, after dividing every device by ``factor``."""
    rig, view = scene.rig, scene.view
    problems = []
    w, h = (v // factor for v in view.resolution)
    if min(w, h) < MIN_VIEW_PIXELS:
        problems.append(f"view.resolution {list(view.resolution)} gives {w} x {h} (at least {MIN_VIEW_PIXELS} "
                        f"pixels a side)")
    spacing = (rig.rows * (3 ** 0.5 / 2 if rig.lattice == "hex" else 1.0) + 1, rig.cols + 0.5)
    for name in ("lf_camera", "projector"):
        size = getattr(rig, name)
        across = min(size[0] // factor / spacing[1], size[1] // factor / spacing[0])
        if across < MIN_PIXELS_PER_LENSLET:
            problems.append(f"rig.{name} {list(size)} gives {size[0] // factor} x {size[1] // factor}, "
                            f"{across:.1f} pixels per lenslet for {rig.rows} x {rig.cols} lenslets (at least "
                            f"{MIN_PIXELS_PER_LENSLET})")
    return problems


def check_resolution(scene, quick: bool = False) -> None:
    """Refuse a scene whose devices are too small for the pipeline, before any work.

    Args:
        scene: ``SceneConfig``.
        quick: check the sizes that ``--quick`` (:func:`quick_scene`) would give.

    Raises:
        SceneError: naming the scene's file, the fields and the sizes.
    """
    from lftransfer.scenes import SceneError

    problems = _too_small(scene, QUICK_FACTOR if quick else 1)
    if problems:
        name = str(scene.source) if scene.source else "<scene>"
        how = f"--quick divides every device by {QUICK_FACTOR}: " if quick else ""
        raise SceneError(f"{name}: {how}{'; '.join(problems)}" + ("; run it without --quick" if quick and not
                                                                    _too_small(scene) else ""))


def quick_scene(scene):
    """The same scene at a small resolution (for ``--quick``): every device at a quarter size, a third of the
    angular samples (at least 8), a quarter of the ground-truth samples (at least 16).

    Raises:
        SceneError: the quarter sizes are too small (:func:`check_resolution`).
    """
    from lftransfer.scenes import with_overrides

    check_resolution(scene, quick=True)
    rig, view, render = scene.rig, scene.view, scene.render
    return with_overrides(
        scene,
        rig={"lf_camera": [rig.lf_camera[0] // QUICK_FACTOR, rig.lf_camera[1] // QUICK_FACTOR],
             "projector": [rig.projector[0] // QUICK_FACTOR, rig.projector[1] // QUICK_FACTOR],
             "angular_samples": max(8, rig.angular_samples // 3)},
        view={"resolution": [view.resolution[0] // QUICK_FACTOR, view.resolution[1] // QUICK_FACTOR]},
        render={"gt_spp": max(16, render.gt_spp // QUICK_FACTOR)},
    )


def _calibrates(options: RunOptions) -> bool:
    return options.calibration is None and options.rig_model == "calibrated"


def _verifies(options: RunOptions, truth_seed_known: bool = True) -> bool:
    return options.verify and (options.rig.kind == "sim" or (options.rig.kind == "replay" and truth_seed_known))


class CalibrationFailedError(RuntimeError):
    """A calibration step could not measure the rig from its images; the message names the step, why, and the
    sizes that matter."""


def calibrate(rig: Rig, scene, *, progress: Callable[[str], None] | None = None):
    """:func:`lftransfer.calibration.rig.calibrate_rig`, its failures (other than a rig fault) as one
    :class:`CalibrationFailedError` that says what to try.

    Args:
        rig: the rig.
        scene: the synthetic part of the scene.
        progress: called with a message per capture or step.
    """
    from lftransfer.rig.base import RigError

    try:
        return calibrate_rig(rig, scene, progress=progress)
    except RigError:
        raise
    except (ValueError, RuntimeError) as exc:
        r, v = scene.rig, scene.view
        raise CalibrationFailedError(
            f"calibration failed: {exc} (view camera {v.resolution[0]} x {v.resolution[1]}, LF camera "
            f"{r.lf_camera[0]} x {r.lf_camera[1]}, projector {r.projector[0]} x {r.projector[1]} pixels for "
            f"{r.rows} x {r.cols} lenslets; small devices may be too coarse to calibrate: try a larger scene or "
            f"no --quick, a calibration file, or --rig-model nominal)") from exc


NOMINAL = "nominal (rig file)"     # the report's rig_model for the rig file's values


def negative_control_skipped(options: RunOptions) -> str | None:
    """Why the negative control of a run that asks for it (``options.negative_control``) cannot tell anything,
    or None when it runs: it needs the simulated rig with a hidden truth, verification, a run that knows more
    than the nominal model, and at least one bounce."""
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
    if options.bounces == 0:
        return "with 0 bounces no light field crosses the array, so the rig model changes nothing the metrics see"
    return None


def _runs_control(options: RunOptions) -> bool:
    return options.negative_control and negative_control_skipped(options) is None


def count_run_steps(scene, options: RunOptions) -> int:
    """Progress steps of :func:`run_scene` (set-up, calibration, transfer, 6 ground-truth renders unless cached,
    reruns with the other lighting models and the negative control, writing), for a progress bar."""
    primary = count_steps(TransferSettings(bounces=options.bounces))
    other = count_steps(TransferSettings(bounces=options.bounces, bounce_views=False))
    calibration = (count_calibration_steps(scene) if _calibrates(options) else 0) \
        + (1 if _calibrates(options) or options.calibration is not None else 0)
    reruns = len(_other_models(scene, options)) + len(_other_choices(scene, options, "reconstruction")) \
        + len(_other_choices(scene, options, "projection")) + len(_other_choices(scene, options, "window")) \
        + (1 if _runs_control(options) else 0)
    return 1 + calibration + primary + (6 if _verifies(options) else 0) + reruns * other + 1


def _other_models(scene, options: RunOptions) -> list[str]:
    primary = options.lighting_model or scene.render.lighting_model
    return [m for m in options.compare_models if m != primary]


#: What a setting of the area model is under the other lighting models.
_NOT_AREA = {"reconstruction": "box", "projection": "box", "window": "cut"}


def _area_choice(scene, options: RunOptions, name: str) -> str:
    """The run's ``name`` ("reconstruction", "projection" or "window"): the option, else the scene's ``render``
    value; "box" ("cut" for the window) unless the area model."""
    if (options.lighting_model or scene.render.lighting_model) != "area":
        return _NOT_AREA[name]
    return getattr(options, name) or getattr(scene.render, name)


def _other_choices(scene, options: RunOptions, name: str) -> list[str]:
    """The values of ``name`` measured beside the run's (``options.compare_<name>s``; none unless the area model)."""
    if (options.lighting_model or scene.render.lighting_model) != "area":
        return []
    primary = _area_choice(scene, options, name)
    return [v for v in getattr(options, f"compare_{name}s") if v != primary]


def write_calibration(path: Path, calibration, truth=None, source: Path | None = None, *,
                      true_lights=None):
    """Write a calibration file, its HTML report and (simulated rig only) its errors against the hidden truth.

    Args:
        path: the calibration file; ``calibration_report.html`` and ``calibration_errors.json`` go beside it (a
            ``calibration_errors.json`` there is removed when there is no truth to compare with).
        calibration: :class:`lftransfer.calibration.rig.Calibration`.
        truth: the simulated rig's true ``RigModel``, or None (a physical rig or a recording: no errors).
        source: the file the calibration was read from, if any: it is not written over with the (shorter)
            calibration read from it.
        true_lights: (3,) per point light, where the simulated rig's lights really stand (world frame), or None.

    Returns:
        The errors (:class:`lftransfer.sim.verify.CalibrationErrors`), or None without a truth.
    """
    from lftransfer.app.calibration_report import write_calibration_report
    from lftransfer.sim.verify import calibration_errors

    path = Path(path)
    if not (source is not None and path.exists() and path.resolve() == Path(source).resolve()):
        calibration.write(path)
    errors = None
    errors_path = path.parent / "calibration_errors.json"
    if truth is not None:
        errors = calibration_errors(calibration, truth, true_lights=true_lights)
        write_json(errors_path, errors.to_json())
    else:
        errors_path.unlink(missing_ok=True)            # an earlier calibration's, which this one does not match
    write_calibration_report(path.parent / "calibration_report.html", calibration, errors)
    return errors


@dataclass
class OpenedRig:
    """A rig opened for a run.

    Attributes:
        rig: the rig the pipeline talks to (wrapped in a recorder when recording).
        truth: the simulated rig's true model (verification only), or None.
        world: the scene as it really is (the simulated rig's hidden world, for the ground truth), or None.
        truth_seed: the hidden truth's seed the world was drawn from (simulated rig or a replay of one).
    """

    rig: Rig
    truth: object | None = None
    world: object | None = None
    truth_seed: int | None = None

    def start_frame(self, index: int) -> None:
        """Begin frame ``index`` of a sequence of independent frames: the simulated rig draws the frame's sensor
        noise from its seed and the index alone (:meth:`lftransfer.sim.SimRig.start_frame`), so the frame is the
        same whichever process renders it and whatever it rendered before. Other rigs have no seed to set."""
        start = getattr(self.rig, "start_frame", None)
        if start is not None:
            start(index)


def open_rig(scene, options: RunOptions, *, operator: Operator | None = None) -> OpenedRig:
    """Open the rig a run asks for (:class:`RigSpec`), wrapped in a recorder when ``options.record`` is set.

    Args:
        scene: the whole scene file (the simulated rig takes its real objects; other rigs ignore them).
        options: see :class:`RunOptions`.
        operator: shows an instruction to the person at a physical rig and waits (hardware rigs only).
    """
    spec = options.rig
    opened = OpenedRig(rig=None)
    if spec.kind == "sim":
        from lftransfer.sim import SimRig, hidden_world

        world, truth = hidden_world(scene, options.truth_seed)
        rig = SimRig(world, truth=truth, capture_spp=options.capture_spp, operator_seed=options.truth_seed)
        opened = OpenedRig(rig=rig, truth=rig.truth, world=world, truth_seed=options.truth_seed)
    elif spec.kind == "hardware":
        from lftransfer.rig.hardware import HardwareRig, load_rig_file

        kwargs = {"operator": operator} if operator is not None else {}
        opened = OpenedRig(rig=HardwareRig(load_rig_file(spec.path), **kwargs))
    elif spec.kind == "replay":
        from lftransfer.rig.replay import ReplayRig

        rig = ReplayRig(spec.path)
        meta = rig.meta or {}
        opened = OpenedRig(rig=rig)
        if meta.get("rig") == "sim" and "truth_seed" in meta:
            from lftransfer.sim import hidden_world

            seed = meta["truth_seed"]
            world, truth = hidden_world(scene, seed)
            opened = OpenedRig(rig=rig, truth=truth, world=world, truth_seed=seed)
    else:
        raise ValueError(f"unknown rig kind {spec.kind!r}")
    if options.record is not None:
        from lftransfer.rig.replay import RecordingRig

        meta = {"rig": spec.kind, "truth_seed": opened.truth_seed if spec.kind == "sim" else None,
                "scene": str(scene.source) if scene.source else None,
                "options": {k: str(v) for k, v in options.__dict__.items()}}
        opened.rig = RecordingRig(opened.rig, options.record, meta=meta)
    return opened


@dataclass(frozen=True)
class Knowledge:
    """What the pipeline knows of a rig before a transfer.

    Attributes:
        model: the rig model (calibrated, nominal or the simulated rig's truth).
        scene: the synthetic part of the scene, its point light where the calibration measured the real one (where
            it really stands for the oracle; the scene file's position for the nominal model).
        calibration: the calibration the model came from, or None.
        rig_model: how the model was had, for reports (``"calibrated"``, ``"true (oracle)"``, :data:`NOMINAL`).
    """

    model: RigModel
    scene: object
    calibration: object | None
    rig_model: str


def _true_lights(opened: OpenedRig) -> list | None:
    """Where the simulated rig's point lights really stand (world frame), or None where the rig hides no truth."""
    return None if opened.world is None else [lt.position for lt in opened.world.lights]


def knowledge(opened: OpenedRig, scene, rig_model: str, *, calibration=None,
              progress: Callable[[str], None] | None = None) -> Knowledge:
    """The rig model and synthetic scene a transfer works with (shared by ``lft run`` and ``lft study``).

    Args:
        opened: the rig.
        scene: the whole scene (only its synthetic part is used).
        rig_model: ``"calibrated"`` (calibrate through the rig now, unless ``calibration`` is given),
            ``"nominal"`` or ``"oracle"`` (:class:`RunOptions`).
        calibration: a calibration already made or loaded (it wins over ``rig_model``).
        progress: called with a message per calibration step.

    Raises:
        ValueError: the oracle on a rig without a known truth.
        CalibrationFailedError: the calibration could not measure the rig.
    """
    ps = scene.synthetic_part()
    label = "calibrated"
    if calibration is None and rig_model == "calibrated":
        calibration = calibrate(opened.rig, ps, progress=progress)
    if calibration is not None:
        model = calibration.model
    elif rig_model == "oracle":
        if opened.truth is None:
            raise ValueError("--rig-model oracle needs the simulated rig's truth (--rig sim)")
        model, label = opened.truth, "true (oracle)"
    else:
        model, label = nominal_rig(scene.rig), NOMINAL
    lights_at = calibration.light_positions(ps) if calibration is not None else \
        _true_lights(opened) if rig_model == "oracle" else None
    if lights_at:
        from lftransfer.scenes import with_overrides

        ps = with_overrides(ps, lights=[lt.model_copy(update={"position": [float(v) for v in at]})
                                        for lt, at in zip(ps.lights, lights_at)])
    return Knowledge(model=model, scene=ps, calibration=calibration, rig_model=label)


def run_scene(scene, out: str | Path, options: RunOptions = RunOptions(), *,
              progress: Progress | None = None, operator: Operator | None = None,
              warn: Warn | None = None) -> dict:
    """Run light field transfer on a scene with the chosen rig and write every output into ``out``.

    ``out/status.json`` says whether the run is ``running``, ``complete``, ``failed`` or ``interrupted``
    (:mod:`lftransfer.app.run_folder`); an earlier run's outputs in ``out`` are removed first, so the folder
    never mixes two runs, and no temporary file stays. Every file is written atomically, so what a failed run
    wrote before its failure stays readable.

    Args:
        scene: ``lftransfer.scenes.SceneConfig`` (a simulated rig takes its real objects as its hidden world; the
            pipeline gets ``scene.synthetic_part()`` only).
        out: output folder (created).
        options: see :class:`RunOptions`.
        progress: called with a description and the number of steps done.
        operator: shows an instruction to the person at a physical rig and waits.
        warn: called with one line for each warning (also listed in the report's ``warnings``): a bad
            ground-truth cache entry, a ground truth too noisy for the error it measures.

    Returns:
        The report (also written as ``report.json``).
    """
    out = Path(out)
    write_status(out, "running", rig=str(options.rig))
    clear_run_folder(out, keep=[options.calibration] if options.calibration is not None else [])
    with tracked_run(out, str(options.rig)):
        opened = None
        try:
            opened = open_rig(scene, options, operator=operator)
            report = _run(scene, out, options, opened, progress, warn)
        finally:
            if opened is not None:
                opened.rig.close()
    return report


SATURATION_WARNING = 0.01       # warn when more of the direct capture's LF camera codes than this are at full scale
BY_MODEL_KEYS = ("cross_transfer_rel_error", "psnr_db", "psnr_objects_db")   # per lighting model and reconstruction


@dataclass(frozen=True)
class ControlRun:
    """A negative control that ran.

    Attributes:
        result: its metrics set against the run's (:class:`lftransfer.sim.verify.NegativeControl`).
        seconds: wall time of the control's transfer and evaluation, s.
    """

    result: NegativeControl
    seconds: float


def _negative_control(rig: Rig, scene, pipeline_scene, settings: TransferSettings, result, gt,
                      step: Callable[[str], None]) -> ControlRun:
    """The run again with the rig file's nominal values (no calibration) on the same rig, set against the run's
    ``result`` on the same ground truth ``gt`` (:func:`lftransfer.sim.verify.negative_control`)."""
    from lftransfer.sim.verify import negative_control

    t = time.perf_counter()
    alt = run_transfer(rig, nominal_rig(scene.rig), pipeline_scene, replace(settings, bounce_views=False),
                       progress=lambda msg: step(f"negative control: {msg}"))
    compared = negative_control(result, alt, gt, NOMINAL)
    return ControlRun(result=compared, seconds=time.perf_counter() - t)


VIEWS_FILE = "views.npz"


def write_views(path: Path, result) -> Path:
    """The view images a run's metrics are computed from, for scoring it later against a truth the run did not
    know (``lft twin score``): ``real_view``, ``real_view_direct``, ``synthetic_rgb``, ``synthetic_alpha`` and
    ``synthetic_direct_rgb`` ((H, W, 3) / (H, W) float32 radiance and coverage)."""
    from lftransfer.imageio_utils import write_npz

    return write_npz(path, real_view=result.real_view, real_view_direct=result.real_view_direct,
                     synthetic_rgb=result.synthetic_view.rgb, synthetic_alpha=result.synthetic_view.alpha,
                     synthetic_direct_rgb=result.bounces[0].synthetic_view.rgb)


def _run(scene, out: Path, options: RunOptions, opened: OpenedRig, progress: Progress | None,
         warn: Warn | None) -> dict:
    done = [0]
    warnings: list[str] = []

    def warning(msg: str) -> None:
        warnings.append(msg)
        if warn:
            warn(msg)

    def step(msg: str) -> None:
        done[0] += 1
        if progress:
            progress(msg, done[0])

    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    step(f"set up the rig ({options.rig})")
    if options.rig_model not in RIG_MODELS:
        raise ValueError(f"rig_model must be one of {RIG_MODELS}, got {options.rig_model!r}")
    if options.rig_model == "oracle" and opened.truth is None:
        raise ValueError("--rig-model oracle needs the simulated rig's truth (--rig sim)")
    rig = opened.rig
    nominal_scene = scene.synthetic_part()         # what the pipeline may know: no real objects, nothing measured
    timings["setup"] = time.perf_counter() - t0
    calibration_errors_ = None
    t = time.perf_counter()
    known = knowledge(opened, scene, options.rig_model, progress=step,
                      calibration=None if options.calibration is None else
                      load_calibration(options.calibration, nominal_scene))
    if options.calibration is not None:
        rig_model = f"calibration file {options.calibration}"
    else:
        rig_model = known.rig_model
        if known.calibration is not None:
            timings["calibration"] = time.perf_counter() - t
    model, pipeline_scene, calibration = known.model, known.scene, known.calibration
    true_lights = _true_lights(opened)
    if calibration is not None:
        step("calibration report")
        calibration_errors_ = write_calibration(out / "calibration.json", calibration, opened.truth,
                                                source=options.calibration, true_lights=true_lights)
    primary = options.lighting_model or scene.render.lighting_model
    render = scene.render
    settings = TransferSettings.for_scene(scene, bounces=options.bounces, lighting_model=primary,
                                          reconstruction=_area_choice(scene, options, "reconstruction"),
                                          projection=_area_choice(scene, options, "projection"),
                                          window=_area_choice(scene, options, "window"),
                                          renderer=options.renderer)
    result = run_transfer(rig, model, pipeline_scene, settings, progress=step)
    for k, v in result.timings_s.items():
        timings[k] = timings.get(k, 0.0) + v

    verified = options.verify and opened.world is not None
    if result.saturated_fraction > SATURATION_WARNING:
        warning(f"{100 * result.saturated_fraction:.2g} % of the LF camera's codes are at full scale in the direct "
                f"capture: the light clipped there does not reach the synthetic side (lower [rig] exposure, or the "
                f"lights' intensity)")
    gt_spp = options.gt_spp if options.gt_spp is not None else render.gt_spp
    gt, metrics, gt_spp_needed = None, None, None
    by_model = {primary: {}}
    by_reconstruction = {settings.reconstruction: {}}
    by_projection = {settings.projection: {}}
    by_window = {settings.window: {}}
    if verified:
        from lftransfer.sim.verify import evaluate, gt_noise_verdict, render_ground_truth

        t = time.perf_counter()
        gt = render_ground_truth(opened.world, spp=gt_spp, use_cache=options.use_cache, progress=step,
                                 warn=warning)
        timings["ground_truth"] = time.perf_counter() - t
        metrics = evaluate(result, gt)
        by_model[primary] = {k: getattr(metrics, k) for k in BY_MODEL_KEYS}
        by_reconstruction[settings.reconstruction] = by_model[primary]
        by_projection[settings.projection] = by_model[primary]
        by_window[settings.window] = by_model[primary]
        noisy = gt_noise_verdict(metrics, gt_spp)
        if noisy is not None:
            warning(noisy.message())
            gt_spp_needed = noisy.spp_needed
    reruns = [("lighting_model", other, by_model, f"transfer_{other}_model")
              for other in _other_models(scene, options)]
    reruns += [("reconstruction", other, by_reconstruction, f"transfer_{other}_reconstruction")
               for other in _other_choices(scene, options, "reconstruction")]
    reruns += [("projection", other, by_projection, f"transfer_{other}_projection")
               for other in _other_choices(scene, options, "projection")]
    reruns += [("window", other, by_window, f"transfer_{other}_window")
               for other in _other_choices(scene, options, "window")]
    for field_name, other, table, timing in reruns:       # the same run with one setting changed, measured
        t = time.perf_counter()
        alt = run_transfer(rig, model, pipeline_scene, replace(settings, **{field_name: other}, bounce_views=False),
                           progress=step)
        if verified:
            m = evaluate(alt, gt)
            table[other] = {k: getattr(m, k) for k in BY_MODEL_KEYS}
        timings[timing] = time.perf_counter() - t
    measured = metrics.to_json() if metrics is not None else {}
    undefined = dict(measured.get("undefined", {}))
    control = None
    if options.negative_control:
        why = negative_control_skipped(options) or (None if verified else "the run is not verified against "
                                                                          "ground truth")
        if why is None:
            control = _negative_control(rig, scene, nominal_scene, settings, result, gt, step)
            timings["negative_control"] = control.seconds
            if not control.result.measurably_worse:
                warning(control.result.message())
        else:
            undefined["negative_control"] = why

    comp = composite(result.synthetic_view.rgb, result.synthetic_view.alpha, result.real_view)
    if not verified:                      # what a later scoring against a truth needs (lft twin score)
        write_views(out / VIEWS_FILE, result)
    stale = getattr(getattr(rig, "inner", rig), "stale_captures", 0)      # a hardware rig's (recorded or not)
    if stale:
        warning(f"{stale} capture(s) saw frames that still changed after the rig file's settle_s: they were "
                "dropped, not averaged, and the captures waited; settle_s is too short (lft calibrate latency)")
    timings["total"] = time.perf_counter() - t0
    from lftransfer.backend import variant

    metric_keys = ("psnr_db", "psnr_db_direct_only", "psnr_objects_db", "psnr_objects_db_direct_only",
                   "cross_transfer_rel_error", "gt_noise_psnr_db", "cross_gt_noise_rel")
    report = {
        **{k: measured.get(k) for k in metric_keys},
        "verification": "against path-traced ground truth" if verified else
        f"none: the {options.rig.kind} rig's real scene is not known to lftransfer",
        "lighting_model": primary,
        "by_lighting_model": by_model,
        "reconstruction": settings.reconstruction,
        "projection": settings.projection,
        "by_reconstruction": by_reconstruction,
        "by_projection": by_projection,
        "window": settings.window,
        "by_window": by_window,
        "negative_control": control.result.to_json() if control is not None else None,
        "undefined_metrics": undefined,
        "warnings": warnings,
        "gt_spp_needed": gt_spp_needed,
        "cross_term_rel_size": measured.get("cross_term_rel_size"),
        "cross_by_side": measured.get("cross_by_side"),
        "bounces": [{"index": b.index, "real_energy": b.real_energy, "synthetic_energy": b.synthetic_energy,
                     "projector_gain": b.projector_gain} for b in result.bounces],
        "projector_clipped_fraction": result.clipped_fraction,
        "lf_camera_saturated_fraction": result.saturated_fraction,
        "timings_s": {k: round(v, 3) for k, v in timings.items()},
        "resolution": {
            "lenslets": [scene.rig.rows, scene.rig.cols], "lattice": scene.rig.lattice,
            "lf_camera": list(scene.rig.lf_camera), "projector": list(scene.rig.projector),
            "view": list(scene.view.resolution), "angular_samples": scene.rig.angular_samples,
            "metrics": measured.get("metric_resolution"),
        },
        "gt_spp": gt_spp if verified else None,
        "renderer": resolve_renderer(pipeline_scene, options.renderer),
        "approximations": approximations(pipeline_scene, options.renderer),
        "rig": str(options.rig),
        "truth_seed": opened.truth_seed,
        "rig_model": rig_model,
        "calibration_errors": calibration_errors_.to_json() if calibration_errors_ is not None else None,
        "variant": variant(),
        "scene": str(scene.source) if scene.source else None,
    }
    step("write outputs")
    write_outputs(out, result, gt.image if gt is not None else None, comp, report, captured_raw=result.captured_raw,
                  camera_bits=scene.rig.lf_camera_bits, ceiling=emitter_ceiling(pipeline_scene))
    return report
