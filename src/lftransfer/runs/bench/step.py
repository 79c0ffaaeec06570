"""The speed benchmark: the live loop's own step function, timed frame by frame on the simulated rig.

What is timed is :meth:`lftransfer.transfer.live.LiveTransfer.step`, the function ``lft render --mode live``
calls per frame, with the rig model a run uses (calibrated by default) and the settings the demo and
``lft render`` build from the scene (:func:`transfer_settings`: angular samples, lighting model, aperture
samples, reconstruction, projection, ``render.spp`` rays per light field sample and per view pixel, renderer).
Each frame's stages are split into:

- the pipeline's own stages (:data:`PIPELINE_STAGES`: pose, encode, decode, the captured light field made a light
  of the synthetic scene (``incident_light``: the window's table, the reconstruction's blend), relight + render
  light field, the
  projection prefilter where the scene asks for it, render view, composite): the work a physical rig's computer
  does; ``pipeline_iteration_ms`` is their sum per frame, median over the timed frames after ``warmup`` frames
  (the first compiles the kernels and measures the real scene's depth for the prefilter, the second builds the
  primary rays' culling tiles);
- the rig's capture (:data:`RIG_STAGES`): in the simulated rig, the simulator's rendering of the real scene;
  a physical rig's exposure instead;
- the rest of the step's wall time (``unstaged_ms``): the rig's ``setup`` and ``project`` calls and the step's
  bookkeeping, in no stage of the step's timer, counted in neither.

Beside it, measured in the same run: the ray-casting floor (:mod:`lftransfer.runs.bench.floor`: the step's own
light field and view rays, one intersection each), the fast path's accuracy against the exact path on the same
frame (:mod:`lftransfer.runs.bench.accuracy`) and, optionally, Mitsuba's own path tracer on the light field job
(:mod:`lftransfer.runs.bench.peer`).
"""

from __future__ import annotations

import os
import platform
import resource
import statistics
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from lftransfer.runs.bench.accuracy import FastVsExact, fast_vs_exact
from lftransfer.runs.bench.decoupled import DecoupledRun, run_decoupled
from lftransfer.runs.bench.floor import FloorTiming, RayRecorder, ray_floor
from lftransfer.runs.bench.peer import PeerComparison, peer_comparison
from lftransfer import choices
from lftransfer.settings import Overrides, resolve_settings
from lftransfer.transfer.bounce import TransferSettings
from lftransfer.transfer.latency import motion_latency
from lftransfer.transfer.live import LiveTransfer

__all__ = ["BenchOptions", "BenchResult", "PIPELINE_STAGES", "RIG_STAGES", "Spread",
           "count_bench_steps", "run_bench", "transfer_settings", "with_moving_object"]

Progress = Callable[[str], None]
RIG_STAGES = ("capture", "capture_view")
PIPELINE_STAGES = ("pose", "encode", "decode", "incident_light", "render_lightfield", "prefilter", "surface_target",
                   "steep_room", "render_view", "composite")
"""The pipeline's stages in the order a frame takes them; a frame takes "prefilter" under ``projection = "depth"``,
"surface_target" under ``"solve"`` and "steep_room" under a visible light probe's map with either."""
NOT_WHAT_USERS_RUN = "not what users run: a run uses the calibrated model"


@dataclass(frozen=True)
class BenchOptions:
    """What the benchmark runs.

    Attributes:
        iterations: timed frames (>= 1).
        warmup: frames run first and not timed (>= 1: the first compiles the kernels, the second builds the
            primary rays' culling tiles, :mod:`lftransfer.render.culling`).
        settings: what the bench overrides of the scene's settings (:class:`lftransfer.settings.Overrides`; none:
            as the demo runs; a lighting model, reconstruction, projection or renderer as ``lft run`` may).
        truth_seed: seed of the simulated rig's hidden truth (0: the demo's rig), or None: built exactly as the
            rig file says.
        rig_model: "calibrated" (default: calibrate the simulated rig first, unless ``calibration`` is given),
            "nominal" (the rig file's values) or "oracle" (the hidden truth); the last two are not what a run
            uses and the result says so.
        calibration: a calibration file (from ``lft calibrate`` or the demo's ``calibration.json``), or None.
        recalibrate: calibrate even where the calibration cache holds this rig's calibration.
        accuracy: also compare the step's composite with the exact path's (:mod:`~lftransfer.runs.bench.accuracy`).
        exact_aperture_samples: aperture points per lenslet of that exact reference (area model).
        peer: also time Mitsuba's path tracer on the light field job (:mod:`~lftransfer.runs.bench.peer`).
        peer_max_spp: the largest peer sample count tried.
        decoupled: also run the decoupled loop as ``lft live`` does (:mod:`~lftransfer.runs.bench.decoupled`):
            frames delivered per second with the simulator capturing beside them, capture rate and age, latency.
    """

    iterations: int = 10
    warmup: int = 2
    settings: Overrides = Overrides()
    truth_seed: int | None = 0
    rig_model: choices.RigModel = choices.DEFAULT_RIG_MODEL
    calibration: Path | None = None
    recalibrate: bool = False
    accuracy: bool = True
    exact_aperture_samples: int = 32
    peer: bool = True
    peer_max_spp: int = 4096
    decoupled: bool = False

    def __post_init__(self) -> None:
        if self.iterations < 1:
            raise ValueError(f"iterations must be >= 1, got {self.iterations}")
        if self.warmup < 1:
            raise ValueError(f"warmup must be >= 1 (the first frame compiles the kernels), got {self.warmup}")
        choices.check_choice("rig_model", self.rig_model, choices.RigModel)


@dataclass(frozen=True)
class Spread:
    """Milliseconds over the timed frames: median, min, max, population standard deviation."""

    median: float
    min: float
    max: float
    stdev: float

    @classmethod
    def of(cls, seconds: list[float]) -> "Spread":
        ms = [1000.0 * s for s in seconds]
        return cls(round(statistics.median(ms), 3), round(min(ms), 3), round(max(ms), 3),
                   round(statistics.pstdev(ms), 3))


@dataclass(frozen=True)
class BenchResult:
    """Everything the benchmark measured, and the settings to reproduce it.

    Attributes:
        pipeline_iteration_ms: the pipeline's share of a frame (sum of :data:`PIPELINE_STAGES`, and of any stage
            the step times that is not a capture), median over the timed frames, ms.
        pipeline_iteration: its spread over the timed frames.
        stages_ms: per pipeline stage, its spread (``render_lightfield`` includes relighting the synthetic scene
            with the decoded light field).
        capture_ms: the rig's capture per frame (:data:`RIG_STAGES`: LF camera and view camera), median, ms.
        rig_stages_ms: per capture stage, its spread.
        unstaged_ms: the step's wall time in no stage (rig setup and projection, bookkeeping), median, ms.
        step_total_ms: the step's whole wall time, median, ms.
        floor_ms: the floor: the step's light field and view rays cast once against the synthetic scene, ms.
        floor: its details (rays per batch, ms per batch, against the renderer's own geometry).
        iteration_over_floor: pipeline_iteration_ms / floor_ms.
        pipeline_fps: frames per second of the pipeline's share (1000 / pipeline_iteration_ms): what a physical
            rig's computer sustains while its cameras expose.
        step_fps: frames per second of the whole step on the simulated rig (1000 / step_total_ms; the simulator's
            capture included).
        fast_vs_exact: the fast path's accuracy on the last timed frame, or None (not asked for).
        peer: Mitsuba's path tracer on the light field job, or None (not asked for).
        settings: the settings used (scene, resolution, samples, models, rig, variant, ...).
        frames_moved: timed frames in which a synthetic object moved (an animated scene).
        cache_vertices: vertices of the fast path's irradiance cache, or None (exact path).
        peak_rss_mb: the process's peak resident memory, MB.
        calibration_s: seconds the bench spent calibrating the rig (0 when it did not).
        latency_ms: motion-to-composite latency (:func:`lftransfer.transfer.latency.motion_latency`): "sync" over
            the timed frames (each capture inside its frame, so on the simulated rig the simulator's capture is in
            it) and "decoupled" (the decoupled run's, or None); each None where nothing moved.
        decoupled: the decoupled loop's run (:class:`~lftransfer.runs.bench.decoupled.DecoupledRun`), or None.
        surface_solve: the projection's solve against the measured surface (``projection = "solve"``; part of the
            ``encode`` stage), or None: ``points`` (the measured points it fits) and ``rays`` (the rays of their
            target, stage "surface_target"); ``cold_ms`` and ``cold_iterations`` of the first solve after the depth was
            measured (in the warm-up), ``warm_ms`` (the spread over the timed frames' solves) and
            ``warm_iterations`` (median and most); ``last_frame``: the last timed frame's misfit at the measured
            points against the same target solved to convergence and the box light field's
            (:meth:`~lftransfer.transfer.surface_solve.SurfaceSolve.last_misfit`).
    """

    pipeline_iteration_ms: float
    pipeline_iteration: Spread
    stages_ms: dict[str, Spread]
    capture_ms: float
    rig_stages_ms: dict[str, Spread]
    unstaged_ms: float
    step_total_ms: float
    floor_ms: float
    floor: FloorTiming
    iteration_over_floor: float
    pipeline_fps: float
    step_fps: float
    fast_vs_exact: FastVsExact | None
    peer: PeerComparison | None
    settings: dict
    frames_moved: int
    cache_vertices: int | None
    peak_rss_mb: float
    calibration_s: float = 0.0
    notes: list[str] = field(default_factory=list)
    latency_ms: dict = field(default_factory=dict)
    decoupled: DecoupledRun | None = None
    surface_solve: dict | None = None

    def to_json(self) -> dict:
        """JSON-ready dict (nested dataclasses as dicts)."""
        return asdict(self)


LIVE_FPS = 24.0                 # frame rate of the motion --live gives a still scene
LIVE_SLIDE_M = 0.02             # ... its first synthetic object sliding this far along y and back
LIVE_TURN_DEG = 20.0            # ... while turning this far about y and back


def with_moving_object(scene, frames: int):
    """The scene with its first synthetic object moving over ``frames`` frames (``lft bench --live``): it slides
    :data:`LIVE_SLIDE_M` along y (parallel to the array) and back while turning :data:`LIVE_TURN_DEG` about y, at
    :data:`LIVE_FPS`. An animated scene is returned as it is (its own motion is timed).

    Raises:
        ValueError: a still scene without synthetic objects (nothing to move).
    """
    from lftransfer.scenes import with_overrides

    if scene.moving:
        return scene
    if not scene.synthetic:
        raise ValueError("--live: the scene has no synthetic object to move")
    obj = scene.synthetic[0].model_dump()
    x, y, z = obj["translate"]
    rx, ry, rz = obj["rotate_deg"]
    duration = max(frames - 1, 1) / LIVE_FPS
    obj["keyframes"] = [{"time_s": 0.0},
                        {"time_s": duration / 2, "translate": [x, y + LIVE_SLIDE_M, z],
                         "rotate_deg": [rx, ry + LIVE_TURN_DEG, rz]},
                        {"time_s": duration}]
    obj["interpolation"] = "smooth"
    return with_overrides(scene, synthetic=[obj, *scene.synthetic[1:]],
                          animation={"duration_s": duration, "fps": LIVE_FPS})


def transfer_settings(scene, options: BenchOptions = BenchOptions()) -> TransferSettings:
    """The live loop's settings, resolved as a run resolves them (:func:`lftransfer.settings.resolve_settings`)
    from the scene and ``options.settings``."""
    return resolve_settings(scene, options.settings).transfer


def count_bench_steps(scene, options: BenchOptions) -> int:
    """Progress messages of :func:`run_bench` (for a progress bar), calibration included."""
    from lftransfer.calibration.rig import count_calibration_steps
    from lftransfer.runs.rigs import will_calibrate

    calibrates = will_calibrate(scene, _run_options(options))
    report = options.rig_model == "calibrated" or options.calibration is not None      # "calibration report"
    return (2 + (count_calibration_steps(scene) if calibrates else 0) + int(report) + options.warmup
            + options.iterations + 1 + int(options.accuracy) + 3 * int(options.peer) + int(options.decoupled))


def _run_options(options: BenchOptions):
    """The run options a bench's rig and rig model are had with (the simulated rig, as ``lft run`` opens it)."""
    from lftransfer.runs.pipeline import RunOptions

    return RunOptions(truth_seed=options.truth_seed, rig_model=options.rig_model, calibration=options.calibration,
                      recalibrate=options.recalibrate)


def _rig_model(scene, opened, options: BenchOptions, say: Progress) -> tuple[object, str, float]:
    """The rig model the step uses, a label for it, and the seconds spent calibrating: a calibration file, the
    calibration cache or a calibration now (:func:`~lftransfer.runs.rigs.know_rig`, as a run has it; its files go
    to a temporary folder), the oracle or the nominal model."""
    import tempfile

    from lftransfer.runs.rigs import know_rig

    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="lft-bench-") as folder:
        known, _, now = know_rig(opened, scene, _run_options(options), Path(folder) / "calibration.json",
                                 progress=say)
    took = time.perf_counter() - start if now else 0.0
    if now:
        return known.model, f"calibrated (by the bench through the simulated rig, {took:.0f} s)", took
    if options.calibration is not None:
        return known.model, f"calibrated (calibration file {options.calibration})", 0.0
    if options.rig_model == "calibrated":
        return known.model, known.rig_model, 0.0
    return known.model, f"{known.rig_model}: {NOT_WHAT_USERS_RUN}", 0.0


def _settings_json(scene, options: BenchOptions, settings: TransferSettings, rig_model: str) -> dict:
    """The settings of a bench run, JSON-ready (machine: CPUs, platform, load averages over 1, 5 and 15 minutes at
    the end of the run: other work on the machine slows every number)."""
    from lftransfer.backend import blas_thread_counts, blas_threads, variant

    rig, view = scene.rig, scene.view
    return {
        "scene": str(scene.source) if scene.source else None,
        "resolution": {"lenslets": [rig.rows, rig.cols], "lattice": rig.lattice, "lf_camera": list(rig.lf_camera),
                       "projector": list(rig.projector), "view": list(view.resolution)},
        "angular_samples": settings.angular_samples,
        "lf_spp": settings.lf_spp,
        "view_spp": settings.view_spp,
        "aperture_samples": settings.aperture_samples,
        "lighting_model": settings.lighting_model,
        "reconstruction": settings.reconstruction,
        "projection": settings.projection,
        "renderer": {"asked": options.settings.renderer or choices.DEFAULT_RENDERER, "used": settings.renderer},
        "rig": "sim",
        "truth_seed": options.truth_seed,
        "rig_model": rig_model,
        "calibration_file": str(options.calibration) if options.calibration is not None else None,
        "iterations": options.iterations,
        "warmup": options.warmup,
        "animated": bool(scene.moving),
        "variant": variant(),
        "blas_threads": {"asked": blas_threads(), "libraries": blas_thread_counts()},
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                    "load_average": [round(x, 2) for x in os.getloadavg()]},
    }


def _beside(scene, options: BenchOptions, simulator, model, live: LiveTransfer, settings, times: list[float], last,
            say: Progress):
    """What the bench measures beside the timed steps, each where asked for: the decoupled loop's run (on a
    simulated rig of its own, opened as ``lft live`` opens it: ``simulator``, a
    :class:`~lftransfer.settings.SimulatorSettings`), the fast path's accuracy on the last frame, Mitsuba's own path
    tracer on the light field job. Returns (decoupled, accuracy, peer), None where not asked for."""
    from lftransfer.runs.pipeline import RunOptions
    from lftransfer.runs.rigs import open_rig

    decoupled = accuracy = peer = None
    if options.decoupled:
        own = open_rig(scene, RunOptions(truth_seed=options.truth_seed), simulator=simulator)
        try:
            decoupled = run_decoupled(own.rig, model, scene.synthetic_part(), settings, np.asarray(times),
                                      frames=max(options.iterations, 10), simulator=simulator, turns=own.turns,
                                      progress=say)
        finally:
            own.rig.close()
    if options.accuracy:
        say("accuracy: the exact path on the last frame (dense aperture sampling)")
        accuracy = fast_vs_exact(last, live.side, settings, aperture_samples=options.exact_aperture_samples)
    if options.peer:
        peer = peer_comparison(live.side.renderer, model.array, last.captured_lf, spp=settings.lf_spp,
                               seed=settings.seed, repeats=max(3, options.iterations // 2),
                               max_spp=options.peer_max_spp, progress=say)
    return decoupled, accuracy, peer


def _notes(options: BenchOptions, renderer: str, rig_model: str, sync_moved: bool, decoupled,
           extra: list[str]) -> list[str]:
    """What the bench's result says of how it measured: where the fast path approximates, the rig model, the peer,
    what the latencies include, the stages counted beside the usual ones (``extra``)."""
    notes = []
    if renderer == "fast":
        notes.append("the fast path approximates: irradiance cached at the vertices of a fine tessellation "
                     "(the synthetic objects' diffuse light, glossy lobes per ray); "
                     + ("fast_vs_exact measures what that costs in accuracy" if options.accuracy else
                        "its accuracy was not measured (--no-accuracy)"))
    if options.calibration is None and options.rig_model != "calibrated":
        notes.append(f"rig model {rig_model}")
    if options.peer:
        notes.append("peer: the light field render alone in the point model (Mitsuba has no area emitter), "
                     "not the live step")
    if sync_moved:
        notes.append("latency_ms.sync: each capture runs inside its frame, so on the simulated rig the simulator's "
                     "capture is in the latency (a physical rig's exposure would be instead)")
    if decoupled is not None:
        sim = decoupled.simulator
        turns = (f", in turns with the frames (stopped while one renders, then {100 * sim['share']:.0f} % of the "
                 "time)" if sim.get("share") else ", side by side")
        where = (f"in a process of its own ({sim['threads']} Dr.Jit thread(s), nice {sim['nice']}{turns})"
                 if sim["where"] == "process" else "in the render loop's process (one Dr.Jit thread pool)")
        notes.append(f"decoupled: the simulator renders its captures {where}, on the same cores as the render "
                     "loop (what lft live on the simulated rig shows); render_fps_alone is the loop with the "
                     "captures held")
    if extra:
        notes.append(f"stages counted in the pipeline besides the usual ones: {', '.join(extra)}")
    return notes


def _timings(frames) -> dict:
    """:class:`BenchResult`'s timings of the timed frames: the pipeline's stages (every stage but the rig's) and
    their sum per frame, the captures, what no stage timed, the whole step; medians in ms and spreads, and the
    rates they give."""
    stages = [k for k in frames[0].timings_s if k != "total"]
    pipeline = [k for k in stages if k not in RIG_STAGES]
    per_frame = [sum(f.timings_s.get(k, 0.0) for k in pipeline) for f in frames]
    capture = [sum(f.timings_s.get(k, 0.0) for k in RIG_STAGES) for f in frames]
    unstaged = [f.timings_s["total"] - sum(f.timings_s.get(k, 0.0) for k in stages) for f in frames]
    pipeline_ms = round(1000 * statistics.median(per_frame), 3)
    step_ms = round(1000 * statistics.median(f.timings_s["total"] for f in frames), 3)
    return {"pipeline_iteration_ms": pipeline_ms, "pipeline_iteration": Spread.of(per_frame),
            "stages_ms": {k: Spread.of([f.timings_s.get(k, 0.0) for f in frames]) for k in pipeline},
            "capture_ms": round(1000 * statistics.median(capture), 3),
            "rig_stages_ms": {k: Spread.of([f.timings_s.get(k, 0.0) for f in frames]) for k in RIG_STAGES},
            "unstaged_ms": round(1000 * statistics.median(unstaged), 3), "step_total_ms": step_ms,
            "pipeline_fps": round(1000.0 / pipeline_ms, 2) if pipeline_ms > 0 else float("inf"),
            "step_fps": round(1000.0 / step_ms, 3)}


def run_bench(scene, options: BenchOptions = BenchOptions(), *, progress: Progress | None = None) -> BenchResult:
    """Time the live step on the simulated rig, and measure the floor, the accuracy and the peer beside it.

    Args:
        scene: the whole scene (``SceneConfig``: the simulated rig takes its real objects; the pipeline gets
            ``scene.synthetic_part()`` only).
        options: see :class:`BenchOptions`.
        progress: called with a message per step (:func:`count_bench_steps` of them).

    Returns:
        :class:`BenchResult`.
    """
    from lftransfer.runs.pipeline import RunOptions
    from lftransfer.runs.rigs import open_rig

    say = progress or (lambda _m: None)
    say("set up the simulated rig")
    opened = open_rig(scene, RunOptions(truth_seed=options.truth_seed))
    try:
        model, rig_model, calibration_s = _rig_model(scene, opened, options, say)
        resolved = resolve_settings(scene, options.settings, loop="decoupled" if options.decoupled else None)
        settings = resolved.transfer
        say("set up the live loop (renderer, codecs)")
        live = LiveTransfer(opened.rig, model, scene.synthetic_part(), settings)
        renderer = settings.renderer
        times = [float(t) for t in scene.frame_times()]
        frame_index = iter(range(10 ** 9))

        def step():
            return live.step(times[next(frame_index) % len(times)])

        for i in range(options.warmup):
            say(f"warm-up frame {i + 1}/{options.warmup} (kernels, ray tiles)")
            with RayRecorder(live.side.renderer) as recorder:
                step()
        solve = live.side.surface_solve
        solved_before = len(solve.history) if solve is not None else 0
        frames = []
        for i in range(options.iterations):
            say(f"live step {i + 1}/{options.iterations}")
            frames.append(step())
        solves = _surface_solve(solve, solved_before)
        say("floor: the step's rays cast once against the synthetic scene")
        batches = recorder.batches
        floor = ray_floor(live.side.renderer.objects, batches, repeats=options.iterations,
                          renderer_scene=live.side.renderer.scene)
        last = frames[-1]
        sync_latency = motion_latency(list(live.changes), frames, "sync")
        decoupled, accuracy, peer = _beside(scene, options, resolved.simulator, model, live, settings, times, last,
                                            say)
    finally:
        opened.rig.close()

    timed = _timings(frames)
    pipeline = list(timed["stages_ms"])
    notes = _notes(options, renderer, rig_model, sync_latency.view is not None, decoupled,
                   [k for k in pipeline if k not in PIPELINE_STAGES])
    return BenchResult(
        **timed,
        floor_ms=floor.ms,
        floor=floor,
        iteration_over_floor=round(timed["pipeline_iteration_ms"] / floor.ms, 2),
        fast_vs_exact=accuracy,
        peer=peer,
        settings=_settings_json(scene, options, settings, rig_model),
        frames_moved=sum(bool(f.moved) for f in frames),
        cache_vertices=live.side.renderer.cache_size if renderer == "fast" else None,
        peak_rss_mb=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1),
        calibration_s=round(calibration_s, 1),
        notes=notes,
        latency_ms={"sync": _latency(sync_latency),
                    "decoupled": _latency(decoupled.latency) if decoupled is not None else None},
        decoupled=decoupled,
        surface_solve=solves,
    )


def _surface_solve(solve, before: int) -> dict | None:
    """:attr:`BenchResult.surface_solve` from the solve's history (``before``: its length when the timed frames
    began)."""
    if solve is None or not solve.history:
        return None
    history = list(solve.history)
    cold = next((r for r in history if not r.warm), None)
    timed = history[before:] if before < len(history) else []
    warm = [r for r in timed if r.warm]
    return {"points": solve.points, "rays": solve.rays, "last_frame": solve.last_misfit(),
            "cold_ms": round(1000 * cold.seconds, 1) if cold else None,
            "cold_iterations": cold.iterations if cold else None,
            "warm_ms": asdict(Spread.of([r.seconds for r in warm])) if warm else None,
            "warm_iterations": {"median": statistics.median(r.iterations for r in warm),
                                "max": max(r.iterations for r in warm)} if warm else None,
            "timed_solves": len(timed), "cold_in_timed": len(timed) - len(warm)}


def _latency(latency) -> dict | None:
    """{"view": ..., "light": ...} of a latency (object or its JSON), None where nothing moved."""
    data = latency if isinstance(latency, dict) else latency.to_json()
    return None if data["view"] is None and data["light"] is None else {"view": data["view"], "light": data["light"]}
