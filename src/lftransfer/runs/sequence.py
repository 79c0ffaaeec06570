"""Sequences: ``lft render`` runs light field transfer over the frames of a scene's animation and writes videos.

Two modes (docs/architecture.md, "The bounce loop" and "The live loop"):

- ``live``: the paper's loop, :class:`~lftransfer.transfer.live.LiveTransfer`: one capture and one render per
  frame, each frame's synthetic light field lit by the latest capture, so bounces accumulate over frames;
- ``converged``: every frame is an independent N-bounce transfer (:func:`~lftransfer.transfer.bounce.run_transfer`
  at that frame's time): the reference the live loop converges to when nothing moves.

The output folder holds ``frames/NNNN.exr`` (the composite, linear radiance), ``frames/NNNN.png`` and
``frames/panel_NNNN.png`` (the Fig. 4 panel of the frame), ``composite.mp4`` and ``bounces.mp4`` (the panels),
``report.json`` (settings and per-frame timings and metrics, rewritten after every frame), ``status.json``
(:mod:`lftransfer.runs.run_folder`) and, in live mode, ``state/projected_lf.npz`` (what the projector shows next;
with several light field interfaces, each one's: ``data``, ``data_1``, ...) and, where the projection prefilter
measured it, ``state/depth.npz`` (the real scene's depth: a resumed loop and the exchange check of
:mod:`lftransfer.runs.effects` prefilter with it, as the frames did).
``--resume`` continues after the last finished frame of an interrupted sequence with the same settings.
"""

from __future__ import annotations

import shutil
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Callable, Iterable, Literal

import numpy as np

from lftransfer import choices
from lftransfer.runs.cluster import ClusterSpec, LocalPool, Worker
from lftransfer.runs.pipeline import RunOptions
from lftransfer.runs.rigs import Knowledge, OpenedRig, know_rig, open_rig
from lftransfer.reports.report import bounce_panel, display_scale, emitter_ceiling, live_panel, to_display
from lftransfer.runs.run_folder import tracked_run, write_status
from lftransfer.imageio_utils import write_exr, write_json, write_png, write_video
from lftransfer.lightfield import LightField
from lftransfer.transfer.bounce import TransferResult, TransferSettings, composite_view
from lftransfer.transfer.interfaces import transfer_through
from lftransfer.scenes.interfaces import interface_names
from lftransfer.settings import RunSettings
from lftransfer.transfer.live import LiveTransfer
from lftransfer.render.selection import approximations, visible_steps
from lftransfer.validation import read_json

__all__ = ["ConvergedFrame", "FrameRecord", "FrameWorker", "SequenceError", "SequenceOptions", "acquire_model",
           "converged_frame", "frame_ground_truth", "frame_metrics", "read_depth", "render_sequence",
           "sequence_summary", "sequence_times"]

MODES = ("live", "converged")
STILL_LIVE_FRAMES = 8            # frames of a still scene in live mode when --frames is not given
STATE_FILE = "state/projected_lf.npz"
DEPTH_FILE = "state/depth.npz"

FrameProgress = Callable[["FrameRecord", int, int], None]


class SequenceError(ValueError):
    """Options that do not fit the scene, or a folder that cannot be resumed; the message says which."""


@dataclass(frozen=True)
class SequenceOptions:
    """Options of a sequence.

    Attributes:
        mode: ``"live"`` or ``"converged"`` (module docstring).
        loop: live mode: ``"sync"`` (a capture inside every frame) or ``"decoupled"`` (captures on their own
            thread at the devices' rate, each frame rendered with the newest; frames then depend on the machine's
            timing, and each frame's record says which capture lit it and how far behind it was).
        frames: how many frames (None: every frame of the scene's ``[animation]``; a still scene gets
            :data:`STILL_LIVE_FRAMES` live frames or one converged frame).
        resume: continue after the last finished frame of the folder's sequence.
        verify_every: render the path-traced ground truth of every k-th frame (0: none; simulated rig only) and
            report its metrics.
        cluster: spread the frames and their ground truths over a Ray cluster (:mod:`lftransfer.runs.cluster`;
            converged mode, simulated rig); None: in this process. The frames are bit-identical either way.
    """

    mode: Literal["live", "converged"] = "live"
    loop: choices.LiveLoop = choices.DEFAULT_SEQUENCE_LOOP
    frames: int | None = None
    resume: bool = False
    verify_every: int = 0
    cluster: ClusterSpec | None = None

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise SequenceError(f"mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        choices.check_choice("loop", self.loop, choices.LiveLoop)
        if self.loop != "sync" and self.mode != "live":
            raise SequenceError("--loop decoupled needs --mode live: a converged frame runs the bounce loop")
        if self.cluster is not None and self.mode != "converged":
            raise SequenceError("--cluster needs --mode converged: the live loop is sequential (each frame is lit "
                                "by the one before), only independent frames can be spread over workers")
        if self.frames is not None and not (isinstance(self.frames, int) and self.frames >= 1):
            raise SequenceError(f"frames must be an integer >= 1, got {self.frames!r}")
        if not (isinstance(self.verify_every, int) and self.verify_every >= 0):
            raise SequenceError(f"verify_every must be an integer >= 0, got {self.verify_every!r}")


@dataclass
class FrameRecord:
    """What ``report.json`` keeps of one frame.

    Attributes:
        index: frame number.
        time_s: scene time, seconds.
        seconds: wall time of the frame (transfer, ground truth and writing), s.
        timings_s: seconds per stage of the transfer.
        clipped_fraction: fraction of lit light field samples above the projector's range.
        metrics: :func:`frame_metrics` against the frame's ground truth, or None.
        capture: live mode: the capture that lit the frame: its ``index``, ``time_s`` (the scene time the real
            scene was posed at), ``behind_s`` (the frame's scene time minus it), ``age_s`` (seconds from the
            capture to the composite), ``light_version`` and ``scene_version`` (:class:`LiveFrame`); None
            otherwise.
    """

    index: int
    time_s: float
    seconds: float
    timings_s: dict[str, float]
    clipped_fraction: float
    metrics: dict[str, float | None] | None = None
    capture: dict | None = None

    def to_json(self) -> dict:
        return {**asdict(self), "timings_s": {k: round(v, 4) for k, v in self.timings_s.items()}}


def sequence_times(scene, options: SequenceOptions) -> np.ndarray:
    """(F,) float64 frame times, seconds: the ``[animation]`` frames (the first ``options.frames``; more frames than
    the animation has hold its last pose), or a still scene's frames at time 0."""
    times = scene.frame_times()
    if scene.animation is None:
        n = options.frames or (STILL_LIVE_FRAMES if options.mode == "live" else 1)
        return np.zeros(n)
    if options.frames is None:
        return times
    extra = np.arange(len(times), options.frames) / scene.animation.fps
    return np.concatenate([times, extra])[: options.frames]


def frame_metrics(image: np.ndarray, gt, over: np.ndarray | None = None) -> dict[str, float | None]:
    """A composite against its ground truth, on images box-downsampled as :func:`evaluate` does.

    Args:
        image: (H, W, 3) the frame's composite.
        gt: its ground truth.
        over: (H, W, 3) the same frame put together by the over operator, where the frame's own composite is the
            depth-aware one (for the comparison on the hidden pixels), or None.

    Returns:
        psnr_db (every pixel) and psnr_objects_db (the objects' pixels), both with the ground truth's peak, and
        psnr_real_db: over the pixels where only real objects are seen, with their own peak (dB). A bright
        emitter in view sets the first two's peak and hides errors on dimmer objects; the third does not.
        Where a real object hides a synthetic one (the ground truth's depths), psnr_hidden_db over those pixels,
        and psnr_hidden_over_db, the over operator's there. None where undefined.
    """
    from lftransfer.sim.metrics import downsample, metric_factor, object_mask, psnr

    f = metric_factor(image.shape[1])
    ref = downsample(gt.image, f)
    img = downsample(image, f)
    mask = object_mask(gt, f)
    real = (downsample(gt.alpha_real, f) > 0.5) & (downsample(gt.synthetic_seen, f) < 0.5)
    peak = float(ref.max())
    real_peak = float(ref[real].max()) if real.any() else 0.0
    values = {"psnr_db": psnr(img, ref, peak), "psnr_objects_db": psnr(img, ref, peak, mask=mask),
              "psnr_real_db": psnr(img, ref, real_peak, mask=real) if real.any() else float("nan")}
    hidden = downsample(gt.real_in_front.astype(np.float32), f) > 0
    if hidden.any():
        values["psnr_hidden_db"] = psnr(img, ref, peak, mask=hidden)
        if over is not None:
            values["psnr_hidden_over_db"] = psnr(downsample(over, f), ref, peak, mask=hidden)
    return {k: (v if np.isfinite(v) else None) for k, v in values.items()}


def _settings_key(scene, options: RunOptions, seq: SequenceOptions, settings: TransferSettings, n: int) -> dict:
    """What must match for ``--resume`` to continue a folder's sequence."""
    return {"scene": str(scene.source) if scene.source else None, "mode": seq.mode, "frames": n,
            **({"loop": seq.loop} if seq.loop != "sync" else {}),
            "rig": str(options.rig), "truth_seed": options.truth_seed, "rig_model": options.rig_model,
            "calibration": str(options.calibration) if options.calibration else None,
            "settings": {k: v for k, v in asdict(settings).items() if k != "bounce_views"},
            "resolution": list(scene.view.resolution)}


def acquire_model(opened, scene, options: RunOptions, out: Path, resume: bool,
                  step: Callable[[str], None]) -> Knowledge:
    """What a sequence or a live session knows of the rig, as ``lft run`` has it
    (:func:`~lftransfer.runs.rigs.know_rig`): the rig model from a calibration file, the one a resumed sequence
    kept in ``out/calibration.json``, the calibration cache, a calibration run now (written there), the oracle or
    the nominal model; and the synthetic scene with its point lights where the calibration measured them (the
    oracle: where they really stand).

    Raises:
        SequenceError: the oracle on a rig without a known truth.
    """
    try:
        known, _, _ = know_rig(opened, scene, options, out / "calibration.json", progress=step, resume=resume)
    except ValueError as exc:
        raise SequenceError(str(exc)) from None
    return known


@dataclass
class ConvergedFrame:
    """One converged frame as a worker hands it back (the same in one process and on a cluster).

    Attributes:
        index: frame number.
        time_s: scene time, seconds.
        result: its N-bounce transfer (the LF camera's raw image left out: it stays with the worker).
        ground_truth: its path-traced ground truth (``lftransfer.sim.ground_truth.GroundTruth``), or None.
        seconds: wall time of the transfer and the ground truth, s.
    """

    index: int
    time_s: float
    result: TransferResult
    ground_truth: object | None
    seconds: float


def _projection(seq: SequenceOptions, resolved: RunSettings) -> list[str]:
    """What the sequence's report says of a projection made from the real scene's depth (``[render] projection =
    "depth"`` or ``"solve"``, one sentence): a live loop measures the depth once, and where real objects move the
    resolution made it the box light field (:attr:`RunSettings.adjustments`)."""
    moved = [a for a in resolved.adjustments if a.startswith("projection:")]
    settings = resolved.transfer
    if moved or not settings.prefilters:
        return moved
    made = ("prefiltered from the real scene's depth" if settings.projection == "depth" else
            "solved against the real surface the depth measures")
    if seq.mode != "live":
        return [f"projection: {made}, measured in every frame (one extra frame with the projector white)"]
    return [f"projection: {made}, measured once before the first frame (two extra frames; the real objects "
            "stand still)"]


def _depth_every_frame(scene, settings: TransferSettings) -> bool:
    """Whether a live loop measures the real scene's depth in every frame: for the depth composite, where the
    scene's real objects move (a real object crossing in front of a synthetic one)."""
    return settings.composite == "depth" and any(o.moves for o in scene.real)


def _composite_note(scene, seq: SequenceOptions, settings: TransferSettings) -> list[str]:
    """What the sequence's report says of the depth composite's depth (one sentence), or nothing."""
    if settings.composite != "depth":
        return []
    if seq.mode != "live":
        return ["composite: by depth, the real scene's depth measured in every frame from the LF camera and by "
                "structured light (24 extra view photographs)"]
    outline = (", kept inside the real objects' outline where the view camera is in front of the array (a view "
               "photograph against the clean plate, taken once; docs/architecture.md, \"Occlusion\")")
    if _depth_every_frame(scene, settings):
        return ["composite: by depth, the real scene's depth measured by the LF camera in every frame (two extra "
                f"frames each: the real objects move){outline}; no structured light, which takes 24 photographs"]
    return ["composite: by depth, the real scene's depth measured by the LF camera once, before the first frame "
            f"(the real objects stand still){outline}; no structured light, which takes 24 photographs"]


def converged_frame(opened: OpenedRig, models, scene, settings: TransferSettings, index: int, time_s: float
                    ) -> tuple[TransferResult, float]:
    """Frame ``index`` of a converged sequence: an independent N-bounce transfer at ``time_s``, its random numbers
    drawn from the frame's index (:meth:`OpenedRig.start_frame`), whatever the rig did before.

    Args:
        opened: the rig (one per light field interface, with several).
        models: the rig model of each interface, in the scene's order (:attr:`Knowledge.each_model`).
        scene: the synthetic part of the scene.
        settings: the transfer's settings.

    Returns:
        (the transfer without its LF camera raw image, seconds).
    """
    t0 = time.perf_counter()
    opened.start_frame(index)
    result = transfer_through(opened.each_rig, models, scene, settings, time_s=time_s)
    return replace(result, captured_raw=None), time.perf_counter() - t0


def frame_ground_truth(oracle, time_s: float, spp: int, use_cache: bool):
    """(the path-traced ground truth of the simulated world at ``time_s``, seconds), through the rig's oracle
    (:meth:`lftransfer.sim.oracle.Oracle.ground_truth`; cached)."""
    t0 = time.perf_counter()
    gt = oracle.ground_truth(spp=spp, world=oracle.world.at(time_s), use_cache=use_cache)
    return gt, time.perf_counter() - t0


class FrameWorker(Worker):
    """A cluster worker of converged sequences (:class:`lftransfer.runs.cluster.WorkerPool`): its own simulated rig,
    warm between frames.

    Args:
        scene: the whole scene (the simulated rig's hidden world).
        options: the run's options (the rig, its truth seed, the ground truth's samples).
        models: the rig model of each interface the driver calibrated or chose.
        settings: the transfer's settings.
        synthetic: the synthetic scene the driver knows (its point lights where calibrated), or None: the scene's.
        threads: Dr.Jit threads (:class:`lftransfer.runs.cluster.Worker`).
    """

    def __init__(self, scene, options: RunOptions, models, settings: TransferSettings, synthetic=None,
                 threads: int | None = None):
        super().__init__(threads)
        self.opened = open_rig(scene, options, interfaces=True)
        self.models, self.settings = models, settings
        self.scene = synthetic if synthetic is not None else scene.synthetic_part()

    def transfer(self, index: int, time_s: float, spp: int | None, use_cache: bool) -> ConvergedFrame:
        """:func:`converged_frame` and, where ``spp`` is given, :func:`frame_ground_truth`."""
        result, seconds = converged_frame(self.opened, self.models, self.scene, self.settings, index, time_s)
        gt = None
        if spp is not None:
            gt, gt_seconds = frame_ground_truth(self.opened.oracle, time_s, spp, use_cache)
            seconds += gt_seconds
        return ConvergedFrame(index, time_s, result, gt, seconds)


def _resumed(out: Path, seq: SequenceOptions, key: dict) -> tuple[list[dict], float | None]:
    """With ``--resume``, the finished frames of the sequence in ``out`` (its settings must match ``key``; a live
    loop continues after its last unbroken frame) and its display scale; else ([], None), with an earlier
    sequence's frames, state and outputs removed from ``out``."""
    report_path = out / "report.json"
    done: list[dict] = []
    scale = None
    if seq.resume:
        if not report_path.is_file():
            raise SequenceError(f"--resume: {report_path} does not exist: nothing to resume")
        old = read_json(report_path, "sequence report", SequenceError)
        if not isinstance(old, dict):
            raise SequenceError(f"--resume: {report_path}: not a sequence report")
        if old.get("key") != key:
            raise SequenceError(f"--resume: {out} holds a sequence with other settings ({old.get('key')}); "
                                f"run without --resume to start again")
        done = [f for f in old.get("frames", []) if (out / "frames" / f"{f['index']:04d}.exr").is_file()]
        if seq.mode == "live":       # the live loop continues after its last unbroken frame
            done = done[:next((i for i, f in enumerate(done) if f["index"] != i), len(done))]
        scale = old.get("display_scale")
    else:
        for sub in ("frames", "state"):
            shutil.rmtree(out / sub, ignore_errors=True)
        for name in ("report.json", "composite.mp4", "bounces.mp4", "calibration.json", "calibration_report.html",
                     "calibration_errors.json"):
            (out / name).unlink(missing_ok=True)
    return done, scale


def _stale_captures(report: dict, opened: OpenedRig) -> None:
    """On a hardware rig, the captures that saw frames still changing after the rig file's ``settle_s`` into the
    report's summary, and a warning where there were any."""
    stale = opened.stale_captures
    if stale is not None:          # a hardware rig: captures that saw a change arrive after settle_s
        report["summary"]["stale_captures"] = int(stale)
        if stale:
            report["warnings"] += [f"{stale} capture(s) saw frames that still changed after the rig file's "
                                  "settle_s: they were dropped, not averaged, and the captures waited; "
                                  "settle_s is too short (lft calibrate latency)"]


def render_sequence(scene, out: str | Path, options: RunOptions = RunOptions(), seq: SequenceOptions = SequenceOptions(),
                    *, progress: FrameProgress | None = None,
                    step: Callable[[str], None] | None = None) -> dict:
    """Render a sequence (module docstring) and write it into ``out``.

    Every frame is written as soon as it is finished; converged frames may finish in any order (on a cluster),
    and a resumed converged sequence renders only the frames that are missing.

    Args:
        scene: ``SceneConfig`` (the simulated rig takes its real objects and their keyframes).
        out: the output folder (made).
        options: the rig, the rig model and the settings (:class:`RunOptions`: N bounces of each converged
            frame, the renderer, the ground truth's samples; the rest from the scene's ``[render]``).
        seq: :class:`SequenceOptions`.
        progress: called after each frame with its record, the frames done and the total.
        step: called with a message during set-up (calibration).

    Returns:
        The report (also ``report.json``).
    """
    out = Path(out)
    step = step or (lambda _msg: None)
    times = sequence_times(scene, seq)
    n = len(times)
    resolved = options.resolve(scene, live=seq.mode == "live", loop=seq.loop if seq.mode == "live" else None,
                               bounce_views=seq.mode == "converged")
    settings, projection_note = resolved.transfer, _projection(seq, resolved)
    if seq.cluster is not None and options.rig.kind != "sim":
        raise SequenceError(f"--cluster needs the simulated rig (--rig sim), not {options.rig}: a physical rig or a "
                            f"recording is one device whose frames come one after another")
    key = _settings_key(scene, options, seq, settings, n)
    report_path = out / "report.json"
    done, scale = _resumed(out, seq, key)
    (out / "frames").mkdir(parents=True, exist_ok=True)
    write_status(out, "running", rig=str(options.rig))
    with tracked_run(out, str(options.rig), interrupted="interrupted (Ctrl-C); --resume continues"):
        opened = None
        try:
            opened = open_rig(scene, options, simulator=resolved.simulator if seq.mode == "live" else None,
                              interfaces=True)
            known = acquire_model(opened, scene, options, out, seq.resume, step)
            rig_model, ps = known.rig_model, known.scene
            report = {"key": key, "mode": seq.mode, "loop": seq.loop if seq.mode == "live" else None,
                      "rig_model": rig_model, "variant": _variant(),
                      "warnings": [*known.warnings, *visible_steps(ps, settings.renderer)],
                      "renderer": settings.renderer, "fps": _fps(scene),
                      "frames_total": n, "display_scale": scale, "frames": done,
                      "projection": settings.projection,
                      "approximations": approximations(ps, settings.renderer, max_depth=settings.max_depth)
                      + projection_note
                      + _composite_note(scene, seq, settings)}
            writer = _FrameWriter(out, report, report_path, ceiling=emitter_ceiling(ps), progress=progress, total=n)
            verify = seq.verify_every > 0 and opened.oracle is not None
            gt_spp = resolved.gt_spp
            if seq.mode == "live":
                _live_frames(writer, opened, known, settings, times, done, out, scene,
                             lambda i: verify and i % seq.verify_every == 0, gt_spp, options.use_cache, seq.loop)
            else:
                finished = {f["index"] for f in done}
                todo = [(i, float(times[i]), gt_spp if verify and i % seq.verify_every == 0 else None,
                         options.use_cache) for i in range(n) if i not in finished]
                if seq.cluster is None:
                    pool = LocalPool(_InProcess(opened, known.each_model, ps, settings))
                    writer.converged(frame for _, frame in pool.map("transfer", todo))
                else:
                    report["cluster"] = _converged_on_cluster(writer, seq.cluster, scene, options, known.each_model,
                                                              ps, settings, todo, step)
            step("write the videos")
            report["summary"] = sequence_summary(report["frames"])
            _stale_captures(report, opened)
            _write_videos(out, n, report["fps"])
            write_json(report_path, report)
        finally:
            if opened is not None:
                opened.close()
    return report


class _InProcess(FrameWorker):
    """A :class:`FrameWorker` on the rig the driver opened (no cluster)."""

    def __init__(self, opened: OpenedRig, models, scene, settings: TransferSettings) -> None:
        self.opened, self.models, self.scene, self.settings = opened, models, scene, settings


def _converged_on_cluster(writer: "_FrameWriter", spec: ClusterSpec, scene, options: RunOptions, models, synthetic,
                          settings: TransferSettings, todo: list[tuple], step: Callable[[str], None]) -> dict:
    """The converged frames ``todo`` on a Ray cluster, written as they finish; returns what the report keeps of
    the cluster (where, how many workers)."""
    from lftransfer.runs.cluster import WorkerPool, connect

    step(f"start the cluster ({spec})")
    with connect(spec) as info:
        step("start the workers")
        pool = WorkerPool(FrameWorker, (scene, options, models, settings, synthetic), info, spec.workers)
        step(f"frames on {len(pool.actors)} workers")
        writer.converged(frame for _, frame in pool.map("transfer", todo))
        return pool.describe()


class _FrameWriter:
    """Writes each finished frame at once (EXR, PNG, panel, its record in ``report.json``) and calls the progress
    callback. The PNGs share frame 0's display scale, so a frame finished before frame 0 (on a cluster) keeps its
    PNG back until frame 0 is written."""

    def __init__(self, out: Path, report: dict, report_path: Path, *, ceiling: float | None,
                 progress: FrameProgress | None, total: int) -> None:
        self.out, self.report, self.report_path = out, report, report_path
        self.ceiling, self.progress, self.total = ceiling, progress, total
        self.held: dict[int, np.ndarray] = {}

    @property
    def scale(self) -> float | None:
        return self.report["display_scale"]

    def converged(self, frames: Iterable[ConvergedFrame]) -> None:
        """Write converged frames as they come (any order)."""
        for f in frames:
            t0 = time.perf_counter()
            result, gt = f.result, f.ground_truth
            comp = result.composite()
            if f.index == 0 and self.scale is None:
                self.report["display_scale"] = display_scale(comp, ceiling=self.ceiling)
            panel = bounce_panel(result, gt.image if gt is not None else None, comp, ceiling=self.ceiling)
            over = None
            if gt is not None and result.view_depth is not None:
                write_frame_depth(self.out, f.index, result.depth, result.view_depth)
                over = replace(result, view_depth=None).composite()
            self.frame(f.index, f.time_s, comp, panel, result.timings_s, result.clipped_fraction, gt,
                       f.seconds + time.perf_counter() - t0, over=over)

    def frame(self, index: int, time_s: float, comp: np.ndarray, panel: np.ndarray, timings: dict, clipped: float,
              gt, seconds: float, capture: dict | None = None, over: np.ndarray | None = None) -> None:
        """Write one frame and its record (``over``: the frame by the over operator, for :func:`frame_metrics`)."""
        frames = self.out / "frames"
        write_exr(frames / f"{index:04d}.exr", comp)
        write_png(frames / f"panel_{index:04d}.png", panel)
        self.held[index] = comp
        if self.scale is not None:
            for i, held in sorted(self.held.items()):
                write_png(frames / f"{i:04d}.png", to_display(held, self.scale))
            self.held.clear()
        record = FrameRecord(index=index, time_s=time_s, seconds=seconds, timings_s=dict(timings),
                             clipped_fraction=clipped, metrics=frame_metrics(comp, gt, over) if gt is not None else None,
                             capture=capture)
        self.report["frames"].append(record.to_json())
        self.report["frames"].sort(key=lambda r: r["index"])
        write_json(self.report_path, self.report)
        if self.progress:
            self.progress(record, len(self.report["frames"]), self.total)


def _live_frames(writer: _FrameWriter, opened: OpenedRig, known: Knowledge, settings: TransferSettings,
                 times: np.ndarray, done: list[dict], out: Path, scene, verified: Callable[[int], bool], gt_spp: int,
                 use_cache: bool, loop: str = choices.DEFAULT_SEQUENCE_LOOP) -> None:
    """The live loop over the frames after ``done``, each written as it is finished (through every light field
    interface of the scene, each one's projector state kept).

    Decoupled (``loop``): the frames are rendered one after another as fast as the renderer goes, the captures
    running beside them; while a frame's ground truth is rendered and its files written, no new capture begins
    (the one in progress finishes), so that this work, which a live loop does not do, gives the captures no
    head start it would not have."""
    state, depth_file = out / STATE_FILE, out / DEPTH_FILE
    n = len(times)
    models = known.each_model
    projected = None
    if done and state.is_file():
        projected = _read_each(state, "data", len(models))
        if projected is None:
            raise SequenceError(f"--resume: {state} does not hold a light field for each of the {len(models)} "
                                "interfaces")
        projected = [LightField(data, m.array) for data, m in zip(projected, models)]
    elif done:
        raise SequenceError(f"--resume: {state} is missing: the live loop cannot continue where it stopped")
    depth = _read_each(depth_file, "depth", len(models)) if done and depth_file.is_file() else None
    names = interface_names(scene.interfaces)
    with LiveTransfer(opened.rig, known.model, known.scene, settings, projected=projected,
                      time_s=float(times[len(done)]) if len(done) < n else 0.0, depth=depth, loop=loop,
                      depth_every_frame=_depth_every_frame(scene, settings), turns=opened.turns,
                      rigs=opened.rigs, models=known.models) as live:
        live.index = len(done)
        for i in range(len(done), n):
            t0 = time.perf_counter()
            t = float(times[i])
            gt = frame_ground_truth(opened.oracle, t, gt_spp, use_cache)[0] \
                if verified(i) and loop == "sync" else None
            frame = live.step(t)
            with live.captures_paused():
                if verified(i) and loop != "sync":
                    gt = frame_ground_truth(opened.oracle, t, gt_spp, use_cache)[0]
                if writer.scale is None:
                    writer.report["display_scale"] = display_scale(frame.composite, ceiling=writer.ceiling)
                panel = live_panel(frame, gt.image if gt is not None else None, writer.scale,
                                   camera_bits=scene.rig.lf_camera_bits, projector_bits=scene.rig.projector_bits,
                                   names=names)
                _write_state(state, **_each_key("data", [lf.data for lf in live.projected_lfs]))
                if live.depths is not None and not depth_file.is_file():
                    _write_state(depth_file, **_each_key("depth", live.depths))
                if verified(i) and live.view_depth is not None:
                    write_frame_depth(out, i, live.depth, live.view_depth)
                over = composite_view(frame.synthetic_view, frame.real_view, None) \
                    if gt is not None and live.view_depth is not None else None
                writer.frame(i, t, frame.composite, panel, frame.timings_s, frame.clipped_fraction, gt,
                             time.perf_counter() - t0, capture=capture_record(frame), over=over)


def _each_key(key: str, arrays) -> dict[str, np.ndarray]:
    """The state file's arrays of each interface: ``key`` for the first (the only one with one interface),
    ``key_1``, ``key_2``, ... for the others."""
    return {key if i == 0 else f"{key}_{i}": a for i, a in enumerate(arrays)}


def _read_each(path: Path, key: str, n: int) -> list[np.ndarray] | None:
    """:func:`_each_key`'s arrays of ``n`` interfaces from ``path``, or None where it does not hold them all."""
    with np.load(path) as z:
        names = list(_each_key(key, range(n)))
        if not all(name in z.files for name in names) or f"{key}_{n}" in z.files:
            return None
        return [z[name] for name in names]


def capture_record(frame) -> dict:
    """What a sequence's report keeps of the capture that lit a live frame (:class:`FrameRecord`)."""
    return {"index": frame.capture_index, "time_s": round(frame.capture_time_s, 4),
            "behind_s": round(frame.time_s - frame.capture_time_s, 4), "age_s": round(frame.capture_age_s, 4),
            "light_version": frame.light_version, "scene_version": frame.scene_version}


def _variant() -> str:
    from lftransfer.backend import variant

    return variant()


def _fps(scene) -> float:
    return float(scene.animation.fps) if scene.animation is not None else 24.0


RANGED = ("psnr_db", "psnr_objects_db", "psnr_real_db", "psnr_hidden_db", "psnr_hidden_over_db", "real_floor",
          "synthetic_floor", "fidelity_floor", "transfer_over_floor", "reference_spp",
          "reference_noise_over_error")   # the summary's ``KEY_min``, ``_max``


def sequence_summary(frames: list[dict]) -> dict:
    """Frames per second of the transfer (median frame time), the metrics' range over verified frames (those of
    :data:`RANGED` that the frames have) and how many quiet references met their target."""
    seconds = [f["timings_s"].get("total", sum(v for k, v in f["timings_s"].items() if k != "total"))
               for f in frames]
    verified = [f["metrics"] for f in frames if f.get("metrics")]
    out = {"frames": len(frames), "median_frame_s": float(np.median(seconds)) if seconds else None,
           "transfer_fps": float(1.0 / np.median(seconds)) if seconds and np.median(seconds) > 0 else None}
    captured = [f["capture"] for f in frames if f.get("capture")]
    if captured:
        out["captures_used"] = len({c["index"] for c in captured})
        out["capture_behind_s_median"] = float(np.median([c["behind_s"] for c in captured]))
        out["capture_behind_s_max"] = float(max(c["behind_s"] for c in captured))
        out["capture_age_s_median"] = float(np.median([c["age_s"] for c in captured]))
    for key in RANGED:
        values = [m[key] for m in verified if m.get(key) is not None]
        if values:
            out[f"{key}_min"], out[f"{key}_max"] = float(min(values)), float(max(values))
    references = [f["reference"] for f in frames if f.get("reference")]
    if references:
        out["references_met"] = sum(bool(r["met"]) for r in references)
        out["references"] = len(references)
    return out


def read_depth(out: str | Path) -> np.ndarray | None:
    """The real scene's depth a live sequence in ``out`` prefiltered with ((K, V, U) metres, NaN: unknown), or None
    where it has none (box projection, converged mode, or a folder from before it was kept)."""
    path = Path(out) / DEPTH_FILE
    if not path.is_file():
        return None
    with np.load(path) as z:
        return z["depth"]


FRAME_DEPTH = "state/depth_{:04d}.npz"


def write_frame_depth(out: Path, index: int, depth: np.ndarray, view_depth) -> None:
    """The real scene's depth a verified live frame was composited with: the LF camera's ((K, V, U) metres) and
    in the view camera (:class:`~lftransfer.real_depth.ViewDepth`), so that its check composites the frame
    without exchange alike (:func:`read_frame_depth`)."""
    _write_state(Path(out) / FRAME_DEPTH.format(index), depth=depth, view_depth=view_depth.depth,
                 view_sigma=view_depth.sigma, source=np.array(view_depth.source))


def read_frame_depth(out: str | Path, index: int):
    """(depth, view depth) of a verified live frame (:func:`write_frame_depth`), or None where it was not kept
    (the over composite, or a folder from before)."""
    from lftransfer.real_depth import ViewDepth

    path = Path(out) / FRAME_DEPTH.format(index)
    if not path.is_file():
        return None
    with np.load(path) as z:
        return z["depth"], ViewDepth(z["view_depth"], z["view_sigma"], str(z["source"]))


def _write_state(path: Path, **arrays: np.ndarray) -> None:
    """Arrays of the live loop's state (the projector's next light field, the depth), atomically: a resumed live
    loop starts from them."""
    from lftransfer.imageio_utils import write_npz

    write_npz(path, **arrays)


def _write_videos(out: Path, n: int, fps: float) -> None:
    import imageio.v3 as iio

    frames = out / "frames"
    write_video(out / "composite.mp4", (iio.imread(frames / f"{i:04d}.png") for i in range(n)), fps)
    write_video(out / "bounces.mp4", (iio.imread(frames / f"panel_{i:04d}.png") for i in range(n)), fps)
