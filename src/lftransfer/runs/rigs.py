"""Opening the rig a run asks for, and what the pipeline knows of it before a transfer.

A *rig spec* picks the rig: ``sim`` (the digital twin), ``hardware:RIG.toml`` (a physical rig, or the device
twin behind real device interfaces) or ``replay:DIR`` (a recording). An opened rig may come with an
:class:`~lftransfer.sim.oracle.Oracle` (the simulated rig, or a recording of one): the only way the faces read
the hidden truth, to verify a run or to run the ``oracle`` baseline. What the pipeline itself knows
(:class:`Knowledge`) is calibrated through the rig, read from a calibration file or the calibration cache
(:mod:`lftransfer.runs.calibration_cache`), or the rig file's nominal values (:func:`know_rig`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from lftransfer.reports.report import write_json
from lftransfer.calibration.interfaces import calibrate_interfaces, read_calibration
from lftransfer.calibration.rig import calibrate_rig
from lftransfer.runs.calibration_cache import CachedCalibration, inputs_sha256, read_entry, write_entry
from lftransfer.sim.gt_cache import CacheProblem
from lftransfer.rig.base import Rig
from lftransfer.rig.model import RigModel, nominal_interfaces, nominal_rig
from lftransfer.scenes.interfaces import interfaces_named
from lftransfer.transfer.share import TurnTaking

if TYPE_CHECKING:
    from lftransfer.sim.oracle import Oracle

__all__ = ["NOMINAL", "CalibrationFailedError", "Knowledge", "OpenedRig", "RigSpec", "cached_calibration", "calibrate",
           "calibration_key", "know_rig", "knowledge", "open_rig", "will_calibrate", "write_calibration"]

Operator = Callable[[str], None]        # shows an instruction to the person at the rig and waits
NOMINAL = "nominal (rig file)"          # the report's rig_model for the rig file's values


@dataclass(frozen=True)
class RigSpec:
    """Which rig a run uses: ``sim``, ``hardware:RIG.toml`` (``hardware:FRONT.toml,SIDE.toml``: one rig file per
    light field interface of the scene, in its order) or ``replay:DIR``.

    Attributes:
        kind: "sim", "hardware" or "replay".
        path: the (first) rig file (hardware) or the recording's folder (replay).
        paths: every rig file (hardware; one per interface); ``(path,)`` otherwise.
    """

    kind: str = "sim"
    path: Path | None = None
    paths: tuple[Path, ...] = ()

    def __post_init__(self) -> None:
        if not self.paths and self.path is not None:
            object.__setattr__(self, "paths", (self.path,))

    @classmethod
    def parse(cls, text: str) -> "RigSpec":
        """``"sim"``, ``"hardware:RIG.toml[,RIG2.toml...]"`` or ``"replay:DIR"`` -> RigSpec (ValueError naming
        what is wrong)."""
        kind, _, rest = str(text).partition(":")
        if kind == "sim" and not rest:
            return cls("sim")
        if kind == "hardware" and rest:
            paths = tuple(Path(part).expanduser() for part in rest.split(","))
            for path in paths:
                if not path.is_file():
                    raise ValueError(f"--rig {text}: the rig file {path} does not exist")
            return cls(kind, paths[0], paths)
        if kind == "replay" and rest:
            path = Path(rest).expanduser()
            if not (path / "manifest.json").is_file():
                raise ValueError(f"--rig {text}: {path} is not a recording (no manifest.json; make one with lft record)")
            return cls(kind, path)
        raise ValueError(f"--rig {text!r}: expected 'sim', 'hardware:RIG.toml' (one rig file per light field "
                         "interface, separated by commas) or 'replay:DIR'")

    def __str__(self) -> str:
        return self.kind if self.path is None else f"{self.kind}:{','.join(str(p) for p in self.paths)}"


class CalibrationFailedError(RuntimeError):
    """A calibration step could not measure the rig from its images; the message names the step, why, and the
    sizes that matter."""


def calibrate(rig: Rig, scene, *, progress: Callable[[str], None] | None = None, rigs: tuple = ()):
    """:func:`lftransfer.calibration.rig.calibrate_rig` (for a scene of several light field interfaces,
    :func:`lftransfer.calibration.interfaces.calibrate_interfaces` through ``rigs``), its failures (other than a rig
    fault) as one :class:`CalibrationFailedError` that says what to try.

    Args:
        rig: the rig.
        scene: the synthetic part of the scene.
        progress: called with a message per capture or step.
        rigs: with several interfaces, one rig per interface (:attr:`OpenedRig.rigs`).
    """
    from lftransfer.rig.base import RigError

    try:
        if scene.interfaces:
            return calibrate_interfaces(list(rigs), scene, progress=progress)
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


def write_calibration(path: Path, calibration, oracle: Oracle | None = None, source: Path | None = None):
    """Write a calibration file, its HTML report and (where the rig has an oracle) its errors against the truth.

    Args:
        path: the calibration file; ``calibration_report.html`` and ``calibration_errors.json`` go beside it (a
            ``calibration_errors.json`` there is removed when there is no truth to compare with).
        calibration: :class:`lftransfer.calibration.rig.Calibration`.
        oracle: the simulated rig's :class:`~lftransfer.sim.oracle.Oracle`, or None (a physical rig: no errors).
        source: the file the calibration was read from, if any: it is not written over with the (shorter)
            calibration read from it.

    Returns:
        The errors (:class:`lftransfer.sim.calibration_errors.CalibrationErrors`), or None without an oracle.
    """
    from lftransfer.reports.calibration_report import write_calibration_report

    path = Path(path)
    if not (source is not None and path.exists() and path.resolve() == Path(source).resolve()):
        calibration.write(path)
    errors = None
    errors_path = path.parent / "calibration_errors.json"
    if oracle is not None:
        errors = oracle.calibration_errors(calibration)
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
        oracle: the hidden truth behind it (:class:`~lftransfer.sim.oracle.Oracle`: the simulated rig, or a replay
            of a recording made on it), for verification and the oracle baseline only; None for a physical rig.
        turns: how a decoupled live loop's frames take turns with the simulator process
            (:class:`~lftransfer.transfer.share.TurnTaking`, for :class:`~lftransfer.transfer.live.LiveTransfer`);
            None: no simulator process, or one that runs side by side.
        rigs: with several light field interfaces, one rig per interface in the scene's order (``rig`` is the
            first's); empty for one.
    """

    rig: Rig
    oracle: Oracle | None = None
    turns: TurnTaking | None = None
    rigs: tuple = ()

    @property
    def each_rig(self) -> list[Rig]:
        """One rig per light field interface, in the scene's order (``[rig]`` for one)."""
        return list(self.rigs) or [self.rig]

    @property
    def stale_captures(self) -> int | None:
        """On a hardware rig, the captures that saw frames still changing after the rig file's ``settle_s`` (every
        interface's, with several); None for other rigs."""
        counts = [getattr(getattr(r, "inner", r), "stale_captures", None) for r in self.each_rig]
        counts = [int(c) for c in counts if c is not None]
        return sum(counts) if counts else None

    @property
    def truth_seed(self) -> int | None:
        """The hidden truth's seed (None: no oracle, or a rig built exactly as its file says)."""
        return None if self.oracle is None else self.oracle.truth_seed

    def noise_state(self) -> dict:
        """The simulated rig's random streams (every interface's, with several), for the calibration cache."""
        if self.rigs:
            return {"interfaces": [r.noise_state() for r in self.rigs]}
        return self.rig.noise_state()

    def restore_noise_state(self, state: dict) -> None:
        """Set the random streams to ``state`` (:meth:`noise_state`)."""
        if self.rigs:
            for r, own in zip(self.rigs, state["interfaces"]):
                r.restore_noise_state(own)
        else:
            self.rig.restore_noise_state(state)

    def close(self) -> None:
        """Close the rig (every interface's, with several)."""
        for rig in self.each_rig:
            rig.close()

    def start_frame(self, index: int) -> None:
        """Begin frame ``index`` of a sequence of independent frames: the simulated rig draws the frame's sensor
        noise from its seed and the index alone (:meth:`lftransfer.sim.SimRig.start_frame`), so the frame is the
        same whichever process renders it and whatever it rendered before. Other rigs have no seed to set."""
        for rig in self.each_rig:                 # every interface's, with several
            start = getattr(rig, "start_frame", None)
            if start is not None:
                start(index)


def open_rig(scene, options, *, operator: Operator | None = None, simulator=None,
             interfaces: bool = False) -> OpenedRig:
    """Open the rig a run asks for (:class:`RigSpec`), wrapped in a recorder when ``options.record`` is set.

    Args:
        scene: the whole scene file (the simulated rig takes its real objects; other rigs ignore them).
        options: :class:`lftransfer.runs.pipeline.RunOptions` (its rig, truth seed, capture rays, recording).
        operator: shows an instruction to the person at a physical rig and waits (hardware rigs only).
        simulator: a live loop's :class:`~lftransfer.settings.SimulatorSettings` (its ``RunSettings.simulator``):
            with ``where="process"`` the simulated rig renders in a process of its own
            (:class:`lftransfer.sim.process.SimulatorProcess`), in turns with the frames where its ``share`` is
            above 0 (``OpenedRig.turns``); its ``renderer_threads`` set this process's Dr.Jit threads. None: the
            simulated rig in this process, the threads as they are.
        interfaces: the caller runs scenes of several light field interfaces (``OpenedRig.rigs``: ``lft run``,
            ``lft calibrate``, ``lft render``, ``lft live``);
            other callers get a :class:`~lftransfer.scenes.SceneError` for such a scene, not its first interface.
    """
    spec = options.rig
    if scene.interfaces:
        if not interfaces:
            from lftransfer.scenes import SceneError

            raise SceneError(f"{interfaces_named(scene)}: lft run, lft calibrate, lft render and lft live take "
                             "them; benchmarks and studies run one interface so far (docs/interfaces.md)")
        return _open_interfaces(scene, options, simulator, operator)
    if len(spec.paths) > 1:
        from lftransfer.scenes import SceneError

        raise SceneError(f"--rig {spec}: {len(spec.paths)} rig files for a scene of one light field interface "
                         "(several are for a scene's [[interface]] tables, one each)")
    if simulator is not None and simulator.renderer_threads:
        from lftransfer.backend import set_drjit_threads

        set_drjit_threads(simulator.renderer_threads)
    if spec.kind == "sim" and simulator is not None and simulator.where == "process":
        from lftransfer.sim.oracle import hidden_oracle
        from lftransfer.sim.process import SimulatorProcess

        rig = SimulatorProcess(scene, options.truth_seed, capture_spp=options.capture_spp, threads=simulator.threads,
                               nice=simulator.nice, pausable=simulator.share > 0)
        turns = TurnTaking(rig.pause, rig.resume, lambda: rig.busy, simulator.share) if simulator.share > 0 else None
        opened = OpenedRig(rig=rig, oracle=hidden_oracle(scene, options.truth_seed), turns=turns)
    elif spec.kind == "sim":
        from lftransfer.sim.oracle import open_simulated_rig

        rig, oracle = open_simulated_rig(scene, options.truth_seed, capture_spp=options.capture_spp)
        opened = OpenedRig(rig=rig, oracle=oracle)
    elif spec.kind == "hardware":
        from lftransfer.rig.hardware import HardwareRig, load_rig_file

        kwargs = {"operator": operator} if operator is not None else {}
        opened = OpenedRig(rig=HardwareRig(load_rig_file(spec.path), **kwargs))
    elif spec.kind == "replay":
        from lftransfer.rig.replay import ReplayRig
        from lftransfer.sim.oracle import oracle_of_recording

        rig = ReplayRig(spec.path)
        opened = OpenedRig(rig=rig, oracle=oracle_of_recording(scene, rig.meta or {}))
    else:
        raise ValueError(f"unknown rig kind {spec.kind!r}")
    if options.record is not None:
        from lftransfer.rig.replay import RecordingRig

        meta = {"rig": spec.kind, "truth_seed": opened.truth_seed if spec.kind == "sim" else None,
                "scene": str(scene.source) if scene.source else None,
                "options": {k: str(v) for k, v in options.__dict__.items()}}
        opened.rig = RecordingRig(opened.rig, options.record, meta=meta)
    return opened


def _open_interfaces(scene, options, simulator, operator) -> OpenedRig:
    """The rigs of a scene with several interfaces: the simulated rig in this process, or a physical rig (the device
    twin) with one rig file per interface in the scene's order (:func:`lftransfer.rig.hardware.open_interfaces`)."""
    from lftransfer.scenes import SceneError

    names = interfaces_named(scene)
    if options.rig.kind == "hardware":
        from lftransfer.rig.hardware import load_rig_file, open_interfaces

        paths = options.rig.paths
        if len(paths) != len(scene.interfaces):
            raise SceneError(f"{names}: --rig {options.rig} names {len(paths)} rig file(s); give one per interface, "
                             "in that order, separated by commas (hardware:FIRST.toml,SECOND.toml)")
        if options.record is not None:
            raise SceneError(f"{names}: a recording holds one interface's devices (no --record)")
        rigs = open_interfaces([load_rig_file(p) for p in paths], operator)
        return OpenedRig(rig=rigs[0], rigs=tuple(rigs))
    if options.rig.kind != "sim" or (simulator is not None and simulator.where == "process") \
            or options.record is not None:
        raise SceneError(f"{names}: they run on the simulated rig in this process (--rig sim, --simulator thread, "
                         "no recording) or on a physical rig (--rig hardware:, one rig file per interface); a "
                         "recording and the simulator's own process have one interface")
    from lftransfer.sim.oracle import open_simulated_interfaces

    rigs, oracle = open_simulated_interfaces(scene, options.truth_seed, capture_spp=options.capture_spp)
    return OpenedRig(rig=rigs[0], oracle=oracle, rigs=tuple(rigs))


@dataclass(frozen=True)
class Knowledge:
    """What the pipeline knows of a rig before a transfer.

    Attributes:
        model: the rig model (calibrated, nominal or the simulated rig's truth).
        scene: the synthetic part of the scene, its point light where the calibration measured the real one (where
            it really stands for the oracle; the scene file's position for the nominal model).
        calibration: the calibration the model came from, or None.
        rig_model: how the model was had, for reports (``"calibrated"``, ``"true (oracle)"``, :data:`NOMINAL`).
        warnings: lines to show and report (a calibration that did not measure the scene's point lights).
        lights_from: where the synthetic side's point lights stand, for reports: "measured by the calibration",
            "the oracle (where they really stand)" or "the scene file".
        models: with several interfaces, each one's model in the scene's order (``model`` is the first's); empty
            for one.
    """

    model: RigModel
    scene: object
    calibration: object | None
    rig_model: str
    warnings: tuple[str, ...] = ()
    lights_from: str = "the scene file"
    models: tuple = ()

    @property
    def each_model(self) -> list[RigModel]:
        """One rig model per light field interface, in the scene's order (``[model]`` for one)."""
        return list(self.models) or [self.model]


def knowledge(opened: OpenedRig, scene, rig_model: str, *, calibration=None, source=None,
              progress: Callable[[str], None] | None = None) -> Knowledge:
    """The rig model and synthetic scene a transfer works with (shared by ``lft run`` and ``lft study``).

    Args:
        opened: the rig.
        scene: the whole scene (only its synthetic part is used).
        rig_model: ``"calibrated"`` (calibrate through the rig now, unless ``calibration`` is given),
            ``"nominal"`` or ``"oracle"`` (:data:`lftransfer.choices.RigModel`).
        calibration: a calibration already made or loaded (it wins over ``rig_model``).
        source: where ``calibration`` was read from, for a warning that names it.
        progress: called with a message per calibration step.

    Raises:
        ValueError: the oracle on a rig without a known truth.
        CalibrationFailedError: the calibration could not measure the rig.
    """
    ps = scene.synthetic_part()
    label = "calibrated"
    models: tuple = ()                # with several interfaces, each one's (model is the first's)
    if calibration is None and rig_model == "calibrated":
        calibration = calibrate(opened.rig, ps, progress=progress, rigs=opened.rigs)
    if calibration is not None:
        model = calibration.model
        models = tuple(getattr(calibration, "models", ()))
    elif rig_model == "oracle":
        if opened.oracle is None:
            raise ValueError("--rig-model oracle needs the simulated rig's truth (--rig sim)")
        model, label, models = opened.oracle.model, "true (oracle)", tuple(opened.oracle.models)
    else:
        models = tuple(nominal_interfaces(scene)) if scene.interfaces else ()
        model, label = models[0] if models else nominal_rig(scene.rig), NOMINAL
    lights_at = calibration.light_positions(ps) if calibration is not None else \
        opened.oracle.true_lights() if rig_model == "oracle" else None
    note = None if calibration is None else calibration.unmeasured_light_note(ps, source or "the calibration")
    lights_from = "the scene file" if not ps.lights or note is not None else \
        "measured by the calibration" if calibration is not None else \
        "the oracle (where they really stand)" if rig_model == "oracle" else "the scene file"
    if lights_at:
        from lftransfer.scenes import with_overrides

        ps = with_overrides(ps, lights=[lt.model_copy(update={"position": [float(v) for v in at]})
                                        for lt, at in zip(ps.lights, lights_at)])
    return Knowledge(model=model, scene=ps, calibration=calibration, rig_model=label,
                     warnings=(note,) if note else (), lights_from=lights_from, models=models)


def calibration_key(scene, options) -> str | None:
    """The calibration cache's key for a run's calibration (:func:`~lftransfer.runs.calibration_cache.inputs_sha256`),
    or None where none is cached: a calibration file given, a rig model other than "calibrated", a rig other than
    the simulated one, or a recording being made (it must hold every request the calibration makes).

    Args:
        scene: the whole scene.
        options: :class:`lftransfer.runs.pipeline.RunOptions` (its rig, rig model, calibration, truth seed, capture
            rays and recording).
    """
    if options.calibration is not None or options.rig_model != "calibrated" or options.rig.kind != "sim" \
            or options.record is not None:
        return None
    return inputs_sha256(scene, options.truth_seed, options.capture_spp)


def cached_calibration(scene, options) -> CachedCalibration | None:
    """The calibration cache's usable entry a run with these options reuses, or None (none cached, not cached for
    this run, ``options.recalibrate``, or an entry that fails its checks)."""
    key = calibration_key(scene, options)
    entry = None if key is None or options.recalibrate else read_entry(key)
    return entry if isinstance(entry, CachedCalibration) else None


def will_calibrate(scene, options) -> bool:
    """Whether a run with these options calibrates through the rig: the rig model "calibrated", no calibration file,
    and no usable entry in the calibration cache (or ``options.recalibrate``)."""
    if options.calibration is not None or options.rig_model != "calibrated":
        return False
    return cached_calibration(scene, options) is None


def _reuse(opened: OpenedRig, scene, options, out_file: Path, resume: bool, warn: Callable[[str], None]):
    """(calibration, label, the file it came from, the cache entry) of a calibration a run reuses, or Nones; a
    cache entry that cannot be used goes to ``warn``."""
    ps = scene.synthetic_part()
    if options.calibration is not None:
        return read_calibration(options.calibration, ps), f"calibration file {options.calibration}", \
            options.calibration, None
    if options.rig_model == "calibrated" and resume and out_file.is_file():
        return read_calibration(out_file, ps), f"calibrated (resumed from {out_file})", out_file, None
    key = calibration_key(scene, options)
    entry = None if key is None or options.recalibrate else read_entry(key)
    if isinstance(entry, CacheProblem):
        warn(entry.message())
    elif entry is not None:
        calibration = read_calibration(entry.calibration_file, ps)
        opened.restore_noise_state(entry.rig_state)           # as the calibrating run's rig stood after calibrating
        return calibration, f"calibrated (reused from the calibration cache, {entry.folder}; --recalibrate makes " \
                            f"a new one)", entry.calibration_file, entry
    return None, None, None, None


def know_rig(opened: OpenedRig, scene, options, out_file: Path, *, progress: Callable[[str], None] | None = None,
             resume: bool = False) -> tuple[Knowledge, dict | None, bool]:
    """What a run knows of its rig, and the calibration written beside its outputs.

    The rig model comes from, in order: a calibration file (``options.calibration``); the one a resumed sequence
    kept (``out_file``, with ``resume``); the calibration cache, on the simulated rig (:func:`calibration_key`;
    not with ``options.recalibrate``), whose entry also sets the rig's random streams to where the calibrating
    run's stood; a calibration now, through the rig (``rig_model`` "calibrated"), then stored in the cache; else
    the oracle or the nominal model (:func:`knowledge`). A calibration is written to ``out_file`` with its report
    and, with an oracle, its errors (copied from the entry when cached; a resumed one is left as it is).

    Args:
        opened: the rig.
        scene: the whole scene.
        options: :class:`lftransfer.runs.pipeline.RunOptions`.
        out_file: where the calibration file goes (``calibration.json`` in the run folder).
        progress: called with a message per calibration step, and "calibration report" when one is written.
        resume: a resumed sequence: reuse ``out_file`` where it exists.

    Returns:
        (the knowledge, its ``rig_model`` the label reports show and its ``warnings`` a cache entry that could not
        be used; the calibration's errors against the hidden truth as ``calibration_errors.json`` holds them, or
        None; whether it calibrated through the rig now).

    Raises:
        ValueError: the oracle on a rig without a known truth.
        CalibrationFailedError: the calibration could not measure the rig.
        CalibrationFileError: a calibration file that does not fit the scene.
    """
    say = progress or (lambda _m: None)
    problems: list[str] = []
    loaded, label, source, cached = _reuse(opened, scene, options, out_file, resume, problems.append)
    known = knowledge(opened, scene, options.rig_model, calibration=loaded, source=source, progress=progress)
    now = loaded is None and known.calibration is not None
    key = calibration_key(scene, options) if now else None
    state = opened.noise_state() if key is not None else None
    errors = None
    resumed = options.calibration is None and source == out_file
    if known.calibration is not None and not resumed:
        say("calibration report")
        if cached is not None:
            cached.copy_to(out_file.parent)
            path = out_file.parent / "calibration_errors.json"
            errors = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else None
        else:
            written = write_calibration(out_file, known.calibration, opened.oracle, source=source)
            errors = None if written is None else written.to_json()
        if key is not None:
            write_entry(key, out_file.parent, state)
    return replace(known, rig_model=label or known.rig_model, warnings=(*problems, *known.warnings)), errors, now
