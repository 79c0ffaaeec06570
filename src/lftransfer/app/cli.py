"""The ``lft`` command.

Everything that can be checked before the work starts is checked first: options and their ranges, the scene
file, a calibration file, the output paths, the ground-truth cache folder and the memory the run needs
(:mod:`lftransfer.app.paths`, :mod:`lftransfer.app.memory`). Errors are one line on stderr with exit code 2 for
bad input (:mod:`lftransfer.app.terminal`); ``lft --debug ...`` shows tracebacks.
"""

from __future__ import annotations

import logging
from contextlib import contextmanager
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table
from typer.core import TyperCommand

from lftransfer.app.terminal import FAILED, INTERRUPTED, LftGroup, console, fail, warn


class _PlainHelp:
    """Help that shows flags without a ``<bool>`` type (mixed into the command and the group)."""

    def get_help_option(self, ctx):  # noqa: ANN001, ANN201
        option = super().get_help_option(ctx)
        if option is not None:
            option.metavar = ""
        return option


class _Command(_PlainHelp, TyperCommand):
    """A command whose help shows flags without a ``<bool>`` type."""


class _Group(_PlainHelp, LftGroup):
    """The ``lft`` group, with the same help."""


app = typer.Typer(cls=_Group, add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="Light field transfer between real and synthetic objects. Errors are one line on stderr "
                       "(exit code 2 for bad input, 1 for a failure, 130 when interrupted).")


@app.callback()
def _main(debug: bool = typer.Option(False, "--debug", metavar="",
                                     help="Show the Python traceback of an unexpected error (may stand anywhere "
                                          "on the command line).")) -> None:
    """Light field transfer between real and synthetic objects."""


def _flag(name: str, help: str) -> bool:  # noqa: A002
    return typer.Option(False, name, metavar="", help=help)


def _parse_memory(text: Optional[str]) -> Optional[int]:
    """``--max-memory`` in bytes (None: not given); a bad size is a usage error naming the option."""
    from lftransfer.app.memory import parse_size

    if text is None:
        return None
    try:
        return parse_size(text)
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="'--max-memory'") from None


_TRUTH_SEED_HELP = "Seed (>= 0) of the simulated rig's hidden truth (how the rig as built differs from the rig file)."
_EXACT_HELP = "Build the simulated rig exactly as the rig file says (no hidden deviations)."
_MODEL_HELP = "What the pipeline knows of the rig: calibrated (calibrate first) | nominal (rig file) | oracle."
_CAL_HELP = "Use this calibration file (from `lft calibrate`) instead of calibrating."
_RIG_HELP = "Which rig: sim (simulated, default) | hardware:RIG.toml (a physical rig) | replay:DIR (a recording)."
_SCENE_HELP = "Scene TOML file, or a built-in scene by name (fig4, fig5, fig6, fig1b)."
_QUICK_HELP = ("Quarter resolution: every device at a quarter of its size, a third of the angular samples (at "
               "least 8), a quarter of the ground-truth samples (at least 16).")
_MEMORY_HELP = ("Largest memory the run may need, e.g. 64G (default: what the machine has available now). The "
                "need is estimated from the scene before any work.")
_BOUNCES_HELP = "Number of bounces (0-20)."
_RENDERER_HELP = "Synthetic renderer: auto (fast where the scene allows) | fast | exact."
_GT_SPP_HELP = "Ground-truth samples per pixel (>= 1; default: the scene's render.gt_spp)."

MAX_BOUNCES = 20


def _truth_seed_option():
    return typer.Option(0, min=0, metavar="N", help=_TRUTH_SEED_HELP)


def _memory_option():
    def check(value: Optional[str]) -> Optional[str]:
        _parse_memory(value)
        return value

    return typer.Option(None, "--max-memory", metavar="SIZE", help=_MEMORY_HELP, callback=check)


def _bounces_option():
    return typer.Option(2, min=0, max=MAX_BOUNCES, metavar="N", help=_BOUNCES_HELP)


def _cluster_option():
    return typer.Option(None, metavar="auto|local|ray://HOST:PORT", help=(
        "Spread the work over a Ray cluster (pip install 'lftransfer[cluster]'): auto (the cluster `ray start` "
        "made here, else a local one) | local (one started for this job) | ray://HOST:PORT. Results are "
        "bit-identical to one process."))


def _workers_option():
    return typer.Option(None, min=1, metavar="N", help="Cluster workers (default: one per GPU, else per CPU core).")


def _cluster_spec(cluster: Optional[str], workers: Optional[int]):
    """``--cluster`` and ``--workers`` -> ClusterSpec, or None for one process (a usage error names the option)."""
    from lftransfer.app.cluster import ClusterSpec

    if cluster is None:
        if workers is not None:
            fail("--workers: needs --cluster")
        return None
    try:
        return ClusterSpec.parse(cluster, workers)
    except ValueError as exc:
        fail(str(exc))


def _rig_spec(rig: str):
    from lftransfer.app.pipeline import RigSpec

    try:
        return RigSpec.parse(rig)
    except ValueError as exc:
        fail(str(exc))


def _rig_options(scene, truth_seed: int, exact_rig: bool, rig_model: str, calibration: Optional[Path],
                 rig: str = "sim") -> dict:
    """The rig part of the run options, checked (a calibration file is read and checked against the scene)."""
    from lftransfer.app.pipeline import RIG_MODELS
    from lftransfer.calibration.rig import load_calibration

    if rig_model not in RIG_MODELS:
        fail(f"--rig-model: expected one of {', '.join(RIG_MODELS)}, got {rig_model!r}")
    spec = _rig_spec(rig)
    if rig_model == "oracle" and spec.kind != "sim":
        fail("--rig-model oracle: only the simulated rig (--rig sim) knows its truth")
    if calibration is not None:
        if not calibration.is_file():
            fail(f"--calibration {calibration}: no such file")
        load_calibration(calibration, scene)              # CalibrationFileError: one line, exit code 2
    return {"truth_seed": None if exact_rig else truth_seed, "rig_model": rig_model, "calibration": calibration,
            "rig": spec}


def _operator(bar: Progress | None = None):
    """The operator callback of a physical rig: show the instruction, wait for Enter (progress bar paused)."""
    import sys

    from lftransfer.rig.base import RigError

    def ask(message: str) -> None:
        if not sys.stdin.isatty():
            raise RigError(f"operator needed but the terminal is not interactive: {message}")
        if bar is not None:
            bar.stop()
        try:
            console.print(f"[bold yellow]operator:[/] {escape(message)}", soft_wrap=True)
            input("  press Enter when done (Ctrl-C to stop) ")
        finally:
            if bar is not None:
                bar.start()

    return ask


def _load(path: Optional[Path], quick: bool):
    """The scene (the built-in Fig. 4 scene for None; a built-in scene's name, e.g. ``fig6``, for a path that does
    not exist and has no suffix), at quarter size with ``quick``; sizes checked."""
    from lftransfer.app.pipeline import check_resolution, quick_scene
    from lftransfer.scenes import builtin_scene, builtin_scenes, load_scene

    if path is not None and not path.exists():
        if path.suffix or str(path) not in builtin_scenes():
            fail(f"{path}: no such file (built-in scenes: {', '.join(builtin_scenes())})")
        path = builtin_scene(str(path))
    scene = load_scene(path if path is not None else builtin_scene("fig4"))    # SceneError: one line, code 2
    if quick:
        return quick_scene(scene)
    check_resolution(scene)
    return scene


def _check_before_work(scene, *, out_dir: Optional[Path] = None, out_file: Optional[Path] = None,
                       out_option: str = "--out", example: Optional[str] = None, cache: bool = False,
                       bounces: int = 2, calibrate: bool = True, max_memory: Optional[str] = None) -> None:
    """Output paths, the ground-truth cache and the memory estimate, before any work (one line, exit code 2)."""
    from lftransfer.app.memory import check_memory, estimate_memory
    from lftransfer.app.paths import check_cache_dir, check_output_dir, check_output_file

    if out_dir is not None:
        check_output_dir(out_dir, out_option)
    if out_file is not None:
        check_output_file(out_file, out_option, example)
    if cache:
        from lftransfer.sim.gt_cache import cache_dir

        check_cache_dir(cache_dir())
    check_memory(estimate_memory(scene, bounces=bounces, calibrate=calibrate), _parse_memory(max_memory))


def _check_renderer(renderer: str) -> None:
    if renderer not in ("auto", "fast", "exact"):
        fail(f"--renderer: expected one of auto, fast, exact, got {renderer!r}")


_PROJECTION_HELP = ("Area model: what the projector is sent: the light field prefiltered from the real scene's "
                    "depth, measured through the rig, or the box light field (default: the scene's).")


def _check_projection(projection: Optional[str]) -> None:
    from lftransfer.transfer.projection import PROJECTIONS

    if projection is not None and projection not in PROJECTIONS:
        fail(f"--projection: expected one of {', '.join(PROJECTIONS)}, got {projection!r}")


_WINDOW_HELP = ("Area model: what the synthetic scene receives from beyond the lenslets' window: the captured "
                "light field read at the window's edge, or nothing (default: the scene's).")


def _check_window(window: Optional[str]) -> None:
    from lftransfer.render.lights import WINDOWS

    if window is not None and window not in WINDOWS:
        fail(f"--window: expected one of {', '.join(WINDOWS)}, got {window!r}")


def _check_reconstruction(reconstruction: Optional[str]) -> None:
    from lftransfer.render.lights import RECONSTRUCTIONS

    if reconstruction is not None and reconstruction not in RECONSTRUCTIONS:
        fail(f"--reconstruction: expected one of {', '.join(RECONSTRUCTIONS)}, got {reconstruction!r}")


def _check_lighting_model(lighting_model: Optional[str]) -> None:
    from lftransfer.render.lights import LIGHTING_MODELS

    if lighting_model is not None and lighting_model not in LIGHTING_MODELS:
        fail(f"--lighting-model: expected one of {', '.join(LIGHTING_MODELS)}, got {lighting_model!r}")


def _run(scene, out: Path, options) -> dict:
    """Run the pipeline with a progress bar; a fault, a calibration file that does not fit or Ctrl-C ends in one
    line that says where the run folder stands."""
    from lftransfer.app.pipeline import CalibrationFailedError, count_run_steps, run_scene
    from lftransfer.calibration.rig import CalibrationFileError
    from lftransfer.rig.base import RigError

    total = count_run_steps(scene, options)
    status = out / "status.json"
    with Progress(TextColumn("[bold]{task.description:<58}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), console=console, transient=False) as bar:
        task = bar.add_task("starting", total=total)

        def progress(msg: str, done: int) -> None:
            bar.update(task, description=escape(msg[:58]), completed=min(done, total))

        try:
            report = run_scene(scene, out, options, progress=progress, operator=_operator(bar), warn=warn)
        except KeyboardInterrupt:
            bar.stop()
            fail(f"interrupted; what was written so far is in {out}, and {status} says 'interrupted'", INTERRUPTED)
        except CalibrationFileError as exc:
            bar.stop()
            fail(str(exc))
        except (RigError, CalibrationFailedError) as exc:
            bar.stop()
            fail(f"{exc} (what was written so far is in {out}; {status} says where it stopped)", FAILED)
        bar.update(task, description="done", completed=total)
    _summary(report, out)
    return report


def _row(table: Table, *cells: object) -> None:
    table.add_row(*(escape(str(c)) for c in cells))


def _control_line(control: dict) -> str:
    """The negative control in one line: its psnr_objects_db and cross error, and the run's margins over it."""
    def num(key: str, spec: str) -> str:
        return "undefined" if control.get(key) is None else format(control[key], spec)

    verdict = "measurably worse" if control["measurably_worse"] else "NOT measurably worse"
    return (f"psnr_objects_db {num('psnr_objects_db', '.4g')} dB, "
            f"cross error {num('cross_transfer_rel_error', '.3g')}; the run better by {num('psnr_objects_margin_db', '+.3g')} dB and {num('cross_error_margin', '+.3g')}: "
            f"{verdict}")


def _summary(report: dict, out: Path) -> None:
    table = Table(title=escape(f"light field transfer -> {out}"))
    table.add_column("metric")
    table.add_column("value", justify="right")
    _row(table, "rig", report["rig"])
    _row(table, "verification", report["verification"])
    undefined = report.get("undefined_metrics") or {}
    for key in ("psnr_db", "psnr_db_direct_only", "psnr_objects_db", "psnr_objects_db_direct_only",
                "cross_transfer_rel_error", "gt_noise_psnr_db", "cross_gt_noise_rel"):
        if report.get(key) is not None:
            _row(table, key, f"{report[key]:.4g}")
        elif key in undefined:
            _row(table, key, "undefined (see below)")
    for name, m in report["by_lighting_model"].items():
        if m.get("cross_transfer_rel_error") is not None:
            _row(table, f"cross error, {name} model", f"{m['cross_transfer_rel_error']:.4g}")
    by_reconstruction = report.get("by_reconstruction") or {}
    for name, m in by_reconstruction.items():
        if len(by_reconstruction) > 1 and m.get("cross_transfer_rel_error") is not None:
            _row(table, f"cross error, {name} reconstruction", f"{m['cross_transfer_rel_error']:.4g}")
    for key, label in (("by_projection", "projection"), ("by_window", "window")):
        by_choice = report.get(key) or {}
        for name, m in by_choice.items():
            if len(by_choice) > 1 and m.get("cross_transfer_rel_error") is not None:
                _row(table, f"cross error, {name} {label}", f"{m['cross_transfer_rel_error']:.4g}")
    control = report.get("negative_control")
    if control is not None:
        _row(table, f"negative control: {control['rig_model']}", _control_line(control))
    for b in report["bounces"]:
        _row(table, f"bounce {b['index']} energy real / synthetic", f"{b['real_energy']:.3g} / {b['synthetic_energy']:.3g}")
    _row(table, "rig model", report["rig_model"])
    errors = report.get("calibration_errors") or {}
    if "lenslet_centre_rms_px" in errors:
        _row(table, "calibration: lenslet centres RMS", f"{errors['lenslet_centre_rms_px']:.3f} px")
    if "pose_position_rms_mm" in errors and "pose_rotation_deg" in errors:
        _row(table, "calibration: pose error", f"{errors['pose_position_rms_mm']:.2f} mm, "
                                                f"{errors['pose_rotation_deg']:.3f} deg")
    _row(table, "total time", f"{report['timings_s']['total']:.1f} s")
    Console().print(table)
    for key, reason in undefined.items():
        Console().print(escape(f"{key} is undefined: {reason}"), soft_wrap=True, highlight=False)


@app.command(cls=_Command)
def demo(out: Path = typer.Option(Path("out/demo"), metavar="DIR", help="Output folder (made if missing)."),
         quick: bool = _flag("--quick", _QUICK_HELP),
         bounces: int = _bounces_option(),
         no_cache: bool = _flag("--no-cache", "Render the ground truth again (do not read or write the cache)."),
         renderer: str = typer.Option("auto", metavar="auto|fast|exact", help=_RENDERER_HELP),
         truth_seed: int = _truth_seed_option(),
         exact_rig: bool = _flag("--exact-rig", _EXACT_HELP),
         rig_model: str = typer.Option("calibrated", metavar="calibrated|nominal|oracle", help=_MODEL_HELP),
         calibration: Optional[Path] = typer.Option(None, metavar="FILE", help=_CAL_HELP),
         rig: str = typer.Option("sim", metavar="SPEC", help=_RIG_HELP),
         max_memory: Optional[str] = _memory_option()) -> None:
    """Run the paper's Fig. 4 scene (10 x 12 hexagonal lenslets), by default on the simulated rig: calibrate,
    transfer, check against ground truth (both lighting models, both reconstructions, both projections, both
    windows) and against a negative control (the rig file's nominal values, uncalibrated)."""
    from lftransfer.app.pipeline import RunOptions

    _check_renderer(renderer)
    scene = _load(None, quick)
    rig_opts = _rig_options(scene, truth_seed, exact_rig, rig_model, calibration, rig)
    options = RunOptions(bounces=bounces, compare_models=("area", "point"), compare_reconstructions=("box", "linear"),
                         compare_projections=("box", "depth"), compare_windows=("edge", "cut"),
                         use_cache=not no_cache, renderer=renderer,
                         negative_control=True, **rig_opts)
    _check_before_work(scene, out_dir=out, cache=not no_cache and rig_opts["rig"].kind != "hardware",
                       bounces=bounces, calibrate=calibration is None and rig_model == "calibrated",
                       max_memory=max_memory)
    _run(scene, out, options)


@app.command(cls=_Command)
def run(scene_file: Path = typer.Argument(..., metavar="SCENE.toml", help=_SCENE_HELP),
        bounces: int = _bounces_option(),
        out: Path = typer.Option(Path("out/run"), metavar="DIR", help="Output folder (made if missing)."),
        lighting_model: Optional[str] = typer.Option(None, metavar="area|point|prefiltered",
                                                     help="Lighting model (default: the scene's)."),
        reconstruction: Optional[str] = typer.Option(None, metavar="linear|box", help=(
            "Area model: how the captured light field is read between lenslets (default: the scene's).")),
        projection: Optional[str] = typer.Option(None, metavar="box|depth", help=_PROJECTION_HELP),
        window: Optional[str] = typer.Option(None, metavar="edge|cut", help=_WINDOW_HELP),
        compare: bool = _flag("--compare-models", "Also measure the other lighting model (area or point), the "
                                                  "other reconstruction (linear or box), the other projection "
                                                  "(depth or box) and the other window (edge or cut)."),
        gt_spp: Optional[int] = typer.Option(None, min=1, metavar="N", help=_GT_SPP_HELP),
        quick: bool = _flag("--quick", _QUICK_HELP),
        no_cache: bool = _flag("--no-cache", "Render the ground truth again (do not read or write the cache)."),
        renderer: str = typer.Option("auto", metavar="auto|fast|exact", help=_RENDERER_HELP),
        truth_seed: int = _truth_seed_option(),
        exact_rig: bool = _flag("--exact-rig", _EXACT_HELP),
        rig_model: str = typer.Option("calibrated", metavar="calibrated|nominal|oracle", help=_MODEL_HELP),
        calibration: Optional[Path] = typer.Option(None, metavar="FILE", help=_CAL_HELP),
        rig: str = typer.Option("sim", metavar="SPEC", help=_RIG_HELP),
        max_memory: Optional[str] = _memory_option()) -> None:
    """Run light field transfer on any scene file with a rig (calibrating it first)."""
    from lftransfer.app.pipeline import RunOptions

    _check_lighting_model(lighting_model)
    _check_reconstruction(reconstruction)
    _check_projection(projection)
    _check_window(window)
    _check_renderer(renderer)
    scene = _load(scene_file, quick)
    rig_opts = _rig_options(scene, truth_seed, exact_rig, rig_model, calibration, rig)
    options = RunOptions(bounces=bounces, lighting_model=lighting_model, reconstruction=reconstruction,
                         projection=projection, window=window,
                         compare_models=("area", "point") if compare else (),
                         compare_reconstructions=("box", "linear") if compare else (),
                         compare_projections=("box", "depth") if compare else (),
                         compare_windows=("edge", "cut") if compare else (), gt_spp=gt_spp,
                         use_cache=not no_cache, renderer=renderer, **rig_opts)
    _check_before_work(scene, out_dir=out, cache=not no_cache and rig_opts["rig"].kind != "hardware",
                       bounces=bounces, calibrate=calibration is None and rig_model == "calibrated",
                       max_memory=max_memory)
    _run(scene, out, options)


@app.command(cls=_Command)
def record(scene_file: Path = typer.Argument(..., metavar="SCENE.toml", help=_SCENE_HELP),
           out: Path = typer.Option(..., "--out", metavar="DIR",
                                    help="Session folder: the recording, and the run's outputs in run/."),
           rig: str = typer.Option("sim", metavar="SPEC", help="Which rig to record: sim | hardware:RIG.toml."),
           bounces: int = _bounces_option(),
           quick: bool = _flag("--quick", _QUICK_HELP),
           renderer: str = typer.Option("auto", metavar="auto|fast|exact", help=_RENDERER_HELP),
           truth_seed: int = _truth_seed_option(),
           exact_rig: bool = _flag("--exact-rig", _EXACT_HELP),
           calibration: Optional[Path] = typer.Option(None, metavar="FILE", help=_CAL_HELP),
           max_memory: Optional[str] = _memory_option()) -> None:
    """Calibrate and run transfer on a rig while storing every request and image it answers (replay it with
    ``lft run SCENE.toml --rig replay:SESSION``)."""
    from lftransfer.app.pipeline import RunOptions

    if rig.startswith("replay"):
        fail("--rig: a recording is recorded already; record from sim or hardware:RIG.toml")
    if (out / "manifest.json").exists():
        fail(f"--out {out}: holds a recording already; choose an empty folder")
    _check_renderer(renderer)
    scene = _load(scene_file, quick)
    rig_opts = _rig_options(scene, truth_seed, exact_rig, "calibrated", calibration, rig)
    options = RunOptions(bounces=bounces, compare_models=(), renderer=renderer, record=out, **rig_opts)
    _check_before_work(scene, out_dir=out, cache=rig_opts["rig"].kind == "sim", bounces=bounces,
                       calibrate=calibration is None, max_memory=max_memory)
    _run(scene, out / "run", options)
    Console().print(escape(f"recorded the session into {out} (replay: lft run {scene_file} --rig replay:{out}"
                           f"{' --quick' if quick else ''} --bounces {bounces})"), soft_wrap=True)


@app.command("live", cls=_Command)
def live(scene_file: Path = typer.Argument(..., metavar="SCENE.toml", help=_SCENE_HELP),
         rig: str = typer.Option("sim", metavar="SPEC", help=_RIG_HELP),
         port: int = typer.Option(8080, min=1, max=65535, metavar="PORT", help="Port of the page on localhost."),
         out: Path = typer.Option(Path("out/live"), metavar="DIR", help="Where 'save' writes frames and scenes."),
         quick: bool = _flag("--quick", _QUICK_HELP),
         truth_seed: int = _truth_seed_option(),
         exact_rig: bool = _flag("--exact-rig", _EXACT_HELP),
         rig_model: str = typer.Option("calibrated", metavar="calibrated|nominal|oracle", help=_MODEL_HELP),
         calibration: Optional[Path] = typer.Option(None, metavar="FILE", help=_CAL_HELP),
         renderer: str = typer.Option("auto", metavar="auto|fast|exact", help=_RENDERER_HELP)) -> None:
    """Run the live loop and show it on a page at http://127.0.0.1:PORT/ until Ctrl-C: the composite and its
    layers, the light field images, the time of every stage and, on demand, the layers of each bounce with their
    display gains; move and edit the synthetic objects (and the real ones on the simulated rig), change the bounces
    and the lighting model, pause, step, reset, save."""
    try:
        from lftransfer.app.viewer.server import serve
    except ImportError as exc:
        fail(f"lft live needs the viewer's packages ({exc.name} is missing): pip install 'lftransfer[viewer]'")
    from lftransfer.app.viewer.command import open_session

    _check_renderer(renderer)
    scene = _load(scene_file, quick)
    rig_opts = _rig_options(scene, truth_seed, exact_rig, rig_model, calibration, rig)
    _check_before_work(scene, out_dir=out, calibrate=calibration is None and rig_model == "calibrated")
    with console.status("setting up the rig (calibrating takes minutes at full resolution)") as status:
        session = open_session(scene, rig=str(rig_opts["rig"]), rig_model=rig_model, calibration=calibration,
                               truth_seed=rig_opts["truth_seed"], out=out, renderer=renderer,
                               progress=lambda msg: status.update(escape(msg[:70])))
    console.print(f"lft live: open http://127.0.0.1:{port}/ (Ctrl-C stops)")
    serve(session, port=port)
    console.print("lft live: stopped")


@app.command("render", cls=_Command)
def render_cmd(scene_file: Path = typer.Argument(..., metavar="SCENE.toml", help=_SCENE_HELP),
               out: Path = typer.Option(Path("out/render"), metavar="DIR", help="Output folder (made if missing)."),
               frames: Optional[int] = typer.Option(None, min=1, metavar="N", help=(
                   "Frames to render (default: every frame of the scene's [animation]; a still scene: 8 live "
                   "frames or 1 converged frame).")),
               mode: str = typer.Option("live", metavar="live|converged", help=(
                   "live: the paper's loop, one capture and one render per frame, bounces accumulating over "
                   "frames | converged: every frame an independent N-bounce transfer.")),
               bounces: int = _bounces_option(),
               resume: bool = _flag("--resume", "Continue after the last finished frame in DIR (same settings)."),
               verify_every: int = typer.Option(0, min=0, metavar="K", help=(
                   "Path trace the ground truth of every K-th frame and report its PSNR (0: none; simulated rig).")),
               gt_spp: Optional[int] = typer.Option(None, min=1, metavar="N", help=_GT_SPP_HELP),
               quick: bool = _flag("--quick", _QUICK_HELP),
               no_cache: bool = _flag("--no-cache", "Render the ground truth again (do not read or write the cache)."),
               renderer: str = typer.Option("auto", metavar="auto|fast|exact", help=_RENDERER_HELP),
               truth_seed: int = _truth_seed_option(),
               exact_rig: bool = _flag("--exact-rig", _EXACT_HELP),
               rig_model: str = typer.Option("calibrated", metavar="calibrated|nominal|oracle", help=_MODEL_HELP),
               calibration: Optional[Path] = typer.Option(None, metavar="FILE", help=_CAL_HELP),
               rig: str = typer.Option("sim", metavar="SPEC", help=_RIG_HELP),
               cluster: Optional[str] = _cluster_option(),
               workers: Optional[int] = _workers_option(),
               max_memory: Optional[str] = _memory_option()) -> None:
    """Render a sequence over the scene's animation: composite.mp4, bounces.mp4, numbered EXR frames and a
    report with per-frame timings (and metrics with --verify-every)."""
    from lftransfer.app.cluster import ClusterError
    from lftransfer.app.pipeline import CalibrationFailedError, RunOptions
    from lftransfer.app.sequence import MODES, SequenceError, SequenceOptions, render_sequence
    from lftransfer.calibration.rig import CalibrationFileError
    from lftransfer.rig.base import RigError

    if mode not in MODES:
        fail(f"--mode: expected one of {', '.join(MODES)}, got {mode!r}")
    _check_renderer(renderer)
    scene = _load(scene_file, quick)
    rig_opts = _rig_options(scene, truth_seed, exact_rig, rig_model, calibration, rig)
    options = RunOptions(bounces=bounces, compare_models=(), gt_spp=gt_spp, use_cache=not no_cache,
                         renderer=renderer, **rig_opts)
    try:
        seq = SequenceOptions(mode=mode, frames=frames, resume=resume, verify_every=verify_every,
                              cluster=_cluster_spec(cluster, workers))
    except SequenceError as exc:
        fail(str(exc))
    if resume and not (out / "report.json").is_file():
        fail(f"--resume: {out / 'report.json'} does not exist: nothing to resume")
    _check_before_work(scene, out_dir=out, cache=verify_every > 0 and not no_cache, bounces=bounces,
                       calibrate=calibration is None and rig_model == "calibrated", max_memory=max_memory)
    status = out / "status.json"
    with Progress(TextColumn("[bold]{task.description:<40}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TextColumn("{task.fields[rate]}"), TimeElapsedColumn(), console=console) as bar:
        task = bar.add_task("set-up", total=None, rate="")
        started = [None, 0]

        def step(msg: str) -> None:
            bar.update(task, description=escape(msg[:40]))

        def progress(record, done: int, total: int) -> None:
            import time

            if started[0] is None:
                started[0], started[1] = time.perf_counter() - record.seconds, done - 1
            elapsed = time.perf_counter() - started[0]
            rate = (done - started[1]) / elapsed if elapsed > 0 else 0.0
            psnr = (record.metrics or {}).get("psnr_objects_db")
            bar.update(task, total=total, completed=done, rate=f"{rate:.2f} frames/s",
                       description=escape(f"frame {record.index} (t = {record.time_s:.2f} s)"
                                          + (f", {psnr:.1f} dB" if psnr is not None else "")))

        try:
            report = render_sequence(scene, out, options, seq, bounces=bounces, progress=progress, step=step)
            check = _check_exchange(scene, out, options, report, step)
        except KeyboardInterrupt:
            bar.stop()
            fail(f"interrupted; the finished frames are in {out}; --resume continues", INTERRUPTED)
        except (SequenceError, CalibrationFileError) as exc:
            bar.stop()
            fail(str(exc))
        except (RigError, CalibrationFailedError, ClusterError) as exc:
            bar.stop()
            fail(f"{exc} (the finished frames are in {out}; {status} says where it stopped)", FAILED)
    summary = report["summary"]
    table = Table(title=escape(f"{mode} sequence -> {out}"))
    table.add_column("")
    table.add_column("value", justify="right")
    _row(table, "frames", str(summary["frames"]))
    if report.get("cluster"):
        c = report["cluster"]
        _row(table, "cluster", f"{c['workers']} workers on {c['address']} ({c['cpus']:g} CPUs, {c['gpus']:g} GPUs)")
    _row(table, "median frame time", f"{summary['median_frame_s']:.3g} s ({summary['transfer_fps']:.3g} frames/s)")
    if "psnr_objects_db_min" in summary:
        _row(table, "psnr over the objects (verified frames)",
             f"{summary['psnr_objects_db_min']:.2f} .. {summary['psnr_objects_db_max']:.2f} dB")
    if "cross_transfer_rel_error_min" in summary:
        _row(table, "cross-transfer error (verified frames)",
             f"{summary['cross_transfer_rel_error_min']:.3f} .. {summary['cross_transfer_rel_error_max']:.3f}"
             + (f" (ground truth's own noise on it: up to {summary['cross_gt_noise_rel_max']:.3f})"
                if summary.get("cross_gt_noise_rel_max") is not None else ""))
    effect = check.effect if check is not None else None
    if effect is not None:
        for name, worst in effect.worst_relative_error().items():
            trend = effect.trend()[name]
            _row(table, f"effect: {name.replace('_', ' ')} against ground truth",
                 "undefined" if worst is None else f"worst {100 * worst:.0f} % off"
                 + ("" if trend is None else f", same trend in {100 * trend:.0f} % of steps"))
        _row(table, "effect curve", f"{out / 'effect.png'}")
    _row(table, "rig model", report["rig_model"])
    if "stale_captures" in summary:
        _row(table, "stale captures (hardware rig)", str(summary["stale_captures"]))
    for note in report["approximations"]:
        _row(table, "approximation", note)
    _row(table, "videos", f"{out / 'composite.mp4'}, {out / 'bounces.mp4'}")
    for line in report.get("warnings", []):
        warn(line)
    Console().print(table)


def _check_exchange(scene, out: Path, options, report: dict, step):
    """The cross errors and the [effect] of a rendered sequence's verified frames (app/effects.py), or None."""
    from lftransfer.app.effects import verify_exchange

    return verify_exchange(scene, out, options, report, step=step)


@app.command("study", cls=_Command)
def study_cmd(study_file: Path = typer.Argument(..., metavar="STUDY.toml", help=(
                  "Study file: [study] (scenes, truth_seeds, rig_model, bounces, quick, gt_spp) and [[setting]] "
                  "tables (name, render = {...}); see docs/architecture.md, 'Scale-out'.")),
              out: Path = typer.Option(Path("out/study"), metavar="DIR", help="Output folder (made if missing)."),
              resume: bool = _flag("--resume", "Keep the cells a previous run of the same study wrote into DIR."),
              no_cache: bool = _flag("--no-cache", "Render the ground truths again (do not read or write the cache)."),
              cluster: Optional[str] = _cluster_option(),
              workers: Optional[int] = _workers_option(),
              max_memory: Optional[str] = _memory_option()) -> None:
    """Scenes x hidden truths x settings -> one table: each cell a converged transfer on the simulated rig, measured
    against its ground truth (study.json, study.md, study.png, study.html)."""
    from lftransfer.app.cluster import ClusterError
    from lftransfer.app.study import StudyError, load_study, run_study

    spec = _cluster_spec(cluster, workers)
    if not study_file.is_file():
        fail(f"{study_file}: no such file")
    try:
        study = load_study(study_file)
    except StudyError as exc:
        fail(str(exc))
    for scene in study.scenes.values():
        _check_before_work(scene, out_dir=out, cache=not no_cache, max_memory=max_memory,
                           calibrate=study.config.rig_model == "calibrated")
    c = study.config
    total = len(c.scenes) * len(c.truth_seeds) * len(c.setting)
    with Progress(TextColumn("[bold]{task.description:<50}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), console=console) as bar:
        task = bar.add_task("set-up", total=total)
        try:
            result = run_study(study, out, cluster=spec, resume=resume, use_cache=not no_cache,
                               progress=lambda msg, done, n: bar.update(task, completed=done,
                                                                        description=escape(msg[:50])))
        except KeyboardInterrupt:
            bar.stop()
            fail(f"interrupted; the finished cells are in {out / 'cells'}; --resume continues", INTERRUPTED)
        except StudyError as exc:
            bar.stop()
            fail(str(exc))
        except ClusterError as exc:
            bar.stop()
            fail(f"{exc} (the finished cells are in {out / 'cells'}; --resume continues)", FAILED)
    Console().print(escape(f"# {result.title}"))
    Console().print(escape(result.markdown()), soft_wrap=True)
    Console().print(escape(f"wrote {out / 'study.html'}, study.json, study.md, study.png ({result.seconds:.0f} s"
                           + (f" on {result.cluster['workers']} workers" if result.cluster else "") + ")"),
                    soft_wrap=True)


@app.command(cls=_Command)
def bench(scene_file: Optional[Path] = typer.Option(None, "--scene", metavar="SCENE.toml",
                                                    help="Scene TOML (default: Fig. 4)."),
          json_out: Optional[Path] = typer.Option(None, "--json", metavar="FILE",
                                                  help="Write the results and the settings used as JSON here."),
          iterations: int = typer.Option(10, min=1, metavar="N",
                                         help="Timed frames of the live step (>= 1), after one warm-up frame."),
          calibration: Optional[Path] = typer.Option(None, metavar="FILE", help=(
              "Use this calibration file (from `lft calibrate`, or the demo's calibration.json) instead of "
              "calibrating the simulated rig first.")),
          rig_model: str = typer.Option("calibrated", metavar="calibrated|nominal|oracle", help=(
              "The rig model the step uses: calibrated (what a run uses, default) | nominal | oracle (neither is "
              "what users run; the output says so).")),
          truth_seed: int = _truth_seed_option(),
          lighting_model: Optional[str] = typer.Option(None, metavar="area|point|prefiltered",
                                                       help="Lighting model (default: the scene's)."),
          reconstruction: Optional[str] = typer.Option(None, metavar="linear|box", help=(
              "Area model: how the captured light field is read between lenslets (default: the scene's).")),
          projection: Optional[str] = typer.Option(None, metavar="box|depth", help=_PROJECTION_HELP),
          renderer: str = typer.Option("auto", metavar="auto|fast|exact", help=_RENDERER_HELP),
          accuracy: bool = typer.Option(True, "--accuracy/--no-accuracy", metavar="", help=(
              "Also render the last frame with the exact path and report the fast path's PSNR against it.")),
          peer: bool = typer.Option(True, "--peer/--no-peer", metavar="", help=(
              "Also time Mitsuba's path integrator on the light field job (point model), at equal RMSE.")),
          quick: bool = _flag("--quick", _QUICK_HELP),
          live: bool = _flag("--live", (
              "Time the step with a synthetic object moving (a still scene's first synthetic object slides 2 cm "
              "and turns 20 degrees and back over the frames; an animated scene moves as its keyframes say).")),
          max_memory: Optional[str] = _memory_option()) -> None:
    """Time the live loop's step (LiveTransfer.step) on the simulated rig with the calibrated rig model and the
    scene's samples: the pipeline's stages apart from the rig's capture, against the floor of casting the step's
    rays once."""
    from lftransfer.app.bench.step import BenchOptions, count_bench_steps, run_bench, with_moving_object
    from lftransfer.app.pipeline import CalibrationFailedError
    from lftransfer.app.report import write_json
    from lftransfer.app.terminal import say
    from lftransfer.rig.base import RigError

    _check_lighting_model(lighting_model)
    _check_reconstruction(reconstruction)
    _check_projection(projection)
    _check_renderer(renderer)
    scene = _load(scene_file, quick)
    if live:
        try:
            scene = with_moving_object(scene, iterations + 1)
        except ValueError as exc:
            fail(str(exc))
    rig_opts = _rig_options(scene, truth_seed, False, rig_model, calibration, "sim")
    calibrates = calibration is None and rig_model == "calibrated"
    _check_before_work(scene, out_file=json_out, out_option="--json", example="bench.json", calibrate=calibrates,
                       max_memory=max_memory)
    options = BenchOptions(iterations=iterations, lighting_model=lighting_model, reconstruction=reconstruction,
                           projection=projection, renderer=renderer, truth_seed=rig_opts["truth_seed"],
                           rig_model=rig_model, calibration=calibration, accuracy=accuracy, peer=peer)
    if calibrates:
        say("The bench calibrates the simulated rig first (the model a run uses): this takes minutes at full "
            "resolution (about 10 on 2 cores; about 1.5 with --quick). --calibration FILE skips it."
            + _demo_calibration_hint(scene))
    try:
        with _step_bar(count_bench_steps(scene, options)) as progress:
            result = run_bench(scene, options, progress=progress)
    except CalibrationFailedError as exc:
        fail(str(exc), FAILED)
    except RigError as exc:
        fail(f"bench failed: {exc}", FAILED)
    data = result.to_json()
    data["settings"]["quick"] = quick
    data["settings"]["live"] = live
    data["settings"]["command"] = _bench_command(scene_file, quick, iterations, calibration, rig_model, truth_seed,
                                                 lighting_model, reconstruction, renderer, accuracy, peer, live,
                                                 projection)
    _bench_table(result)
    if json_out is not None:
        write_json(json_out, data)
        say(f"wrote {json_out}")


def _demo_calibration_hint(scene) -> str:
    """`` The demo's FILE fits this scene: ...`` where the demo's calibration file exists and fits, else ``""``."""
    from lftransfer.calibration.rig import CalibrationFileError, load_calibration

    demo_file = Path("out/demo/calibration.json")
    if not demo_file.is_file():
        return ""
    try:
        load_calibration(demo_file, scene.synthetic_part())
    except CalibrationFileError:
        return ""
    return (f" The demo's {demo_file} fits this scene's rig: --calibration {demo_file} uses it (made for the "
            f"demo's --truth-seed).")


def _bench_command(scene_file, quick, iterations, calibration, rig_model, truth_seed, lighting_model,
                   reconstruction, renderer, accuracy, peer, live=False, projection=None) -> str:
    """The ``lft bench`` command line that reproduces a run (without --json and --max-memory)."""
    import shlex

    parts = ["lft", "bench"]
    if scene_file is not None:
        parts += ["--scene", str(scene_file)]
    if quick:
        parts.append("--quick")
    if live:
        parts.append("--live")
    parts += ["--iterations", str(iterations)]
    if calibration is not None:
        parts += ["--calibration", str(calibration)]
    elif rig_model != "calibrated":
        parts += ["--rig-model", rig_model]
    if truth_seed != 0:
        parts += ["--truth-seed", str(truth_seed)]
    for name, value in (("--lighting-model", lighting_model), ("--reconstruction", reconstruction),
                        ("--projection", projection)):
        if value is not None:
            parts += [name, value]
    if renderer != "auto":
        parts += ["--renderer", renderer]
    if not accuracy:
        parts.append("--no-accuracy")
    if not peer:
        parts.append("--no-peer")
    return shlex.join(parts)


def _bench_table(result) -> None:
    """The bench's results as a table on stdout."""
    s = result.settings
    res = s["resolution"]
    table = Table(title="lft bench: LiveTransfer.step on the simulated rig")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    _row(table, "rig model", s["rig_model"])
    _row(table, "settings", f"{s['lighting_model']} model, {s['reconstruction']} reconstruction, "
                            f"{s['renderer']['used']} renderer, {s['angular_samples']}^2 angular samples, "
                            f"lf {s['lf_spp']} / view {s['view_spp']} spp, {s['aperture_samples']} aperture points")
    _row(table, "resolution", f"LF camera {res['lf_camera'][0]}x{res['lf_camera'][1]}, projector "
                              f"{res['projector'][0]}x{res['projector'][1]}, view {res['view'][0]}x{res['view'][1]}, "
                              f"{res['lenslets'][0]}x{res['lenslets'][1]} lenslets")
    p = result.pipeline_iteration
    _row(table, "pipeline_iteration_ms (median)",
         f"{result.pipeline_iteration_ms:.1f} ms (min {p.min:.1f}, max {p.max:.1f}; {s['iterations']} frames)")
    labels = {"incident_light": "captured light field as a light", "render_lightfield": "relight + render light field"}
    for stage, t in result.stages_ms.items():
        _row(table, f"  {labels.get(stage, stage.replace('_', ' '))}", f"{t.median:.1f} ms")
    rig = result.rig_stages_ms
    _row(table, "rig capture (simulator; not in the pipeline)",
         f"{result.capture_ms:.0f} ms (LF {rig['capture'].median:.0f}, view {rig['capture_view'].median:.0f})")
    _row(table, "rig setup/project, bookkeeping (in neither)", f"{result.unstaged_ms:.1f} ms")
    f = result.floor
    where = {"scene": "the scene's shapes", "renderer": "the renderer's geometry"}[f.geometry]
    _row(table, "floor_ms (the step's rays cast once)", f"{result.floor_ms:.1f} ms ({sum(f.rays):,} rays, "
                                                        f"{where})")
    other = f.renderer_geometry_ms if f.geometry == "scene" else f.scene_geometry_ms
    if other is not None:
        _row(table, "  same rays, the other geometry", f"{other:.1f} ms")
    _row(table, "iteration_over_floor", f"{result.iteration_over_floor:.1f}x")
    _row(table, "frames per second: pipeline / whole step", f"{result.pipeline_fps:.2f} / {result.step_fps:.3f} "
                                                            f"(the step includes the simulator's capture)")
    _row(table, "frames in which a synthetic object moved", f"{result.frames_moved} of {s['iterations']}")
    if result.fast_vs_exact is not None:
        v, o = result.fast_vs_exact.psnr_db, result.fast_vs_exact.psnr_objects_db
        _row(table, "fast vs exact composite PSNR: all / objects", "n/a (exact path)" if v is None else
             f"{v:.1f} dB / " + ("n/a" if o is None else f"{o:.1f} dB"))
    if result.peer is not None:
        q = result.peer
        bound = "" if q.reached_target else " (lower bound: the peer missed our RMSE)"
        _row(table, "peer: light field job, point model", f"ours {q.ours_ms:.0f} ms, Mitsuba path {q.peer_ms:.0f} ms "
                                                          f"at {q.peer_spp} spp")
        _row(table, "peer ratio", f"{q.ratio:.0f}x{bound}")
    _row(table, "variant, peak RSS", f"{s['variant']}, {result.peak_rss_mb:.0f} MB")
    Console().print(table)
    for note in result.notes:
        Console().print(escape(f"note: {note}"), soft_wrap=True, highlight=False)

@contextmanager
def _step_bar(total: int):
    """A progress bar that advances by one on every message; yields the callback."""
    with Progress(TextColumn("[bold]{task.description:<58}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), console=console) as bar:
        task = bar.add_task("starting", total=total)
        done = [0]

        def progress(msg: str) -> None:
            done[0] += 1
            bar.update(task, description=escape(msg[:58]), completed=min(done[0], total))

        yield progress
        bar.update(task, description="done", completed=total)


class _CalibrateGroup(_Group):
    """``lft calibrate SCENE.toml ...`` is ``lft calibrate rig SCENE.toml ...``; other first words name a step."""

    def parse_args(self, ctx, args):
        if args and not args[0].startswith("-") and args[0] not in self.commands:
            args = ["rig", *args]
        return super().parse_args(ctx, args)


calibrate_app = typer.Typer(
    cls=_CalibrateGroup, no_args_is_help=True, subcommand_metavar="SCENE.toml [OPTIONS] | COMMAND [ARGS]...",
    help="Calibrate the rig: lft calibrate SCENE.toml [--out FILE.json] [--quick] [--truth-seed N] [--exact-rig] "
         "[--rig SPEC] [--max-memory SIZE] (the same as lft calibrate rig SCENE.toml ...; see lft calibrate rig "
         "--help). Or run one step on image files (lenslets, intrinsics), measure the projector's latency, or "
         "measure calibration accuracy over hidden truths (seeds).")
app.add_typer(calibrate_app, name="calibrate")


@calibrate_app.command("rig", cls=_Command)
def calibrate_rig_cmd(scene_file: Path = typer.Argument(..., metavar="SCENE.toml", help="Scene TOML file (its rig)."),
                      out: Path = typer.Option(Path("calibration.json"), metavar="FILE.json",
                                               help="Calibration file to write (a file, not a folder); the report "
                                                    "and the errors go beside it."),
                      quick: bool = _flag("--quick", _QUICK_HELP),
                      truth_seed: int = _truth_seed_option(),
                      exact_rig: bool = _flag("--exact-rig", _EXACT_HELP),
                      rig: str = typer.Option("sim", metavar="SPEC", help=_RIG_HELP),
                      max_memory: Optional[str] = _memory_option()) -> None:
    """Run every calibration step through the rig; write the calibration file and its report.

    Also reachable as ``lft calibrate SCENE.toml``. Beside ``--out`` it writes ``calibration_report.html`` and,
    where the rig is simulated and knows its truth, ``calibration_errors.json``.
    """
    from lftransfer.app.pipeline import CalibrationFailedError, RunOptions, calibrate, open_rig, write_calibration
    from lftransfer.calibration.rig import count_calibration_steps
    from lftransfer.rig.base import RigError

    scene = _load(scene_file, quick)
    options = RunOptions(truth_seed=None if exact_rig else truth_seed, rig=_rig_spec(rig))
    _check_before_work(scene, out_file=out, example="calibration.json", max_memory=max_memory)
    try:
        with _step_bar(count_calibration_steps(scene)) as progress:
            opened = open_rig(scene, options, operator=_operator())
            try:
                cal = calibrate(opened.rig, scene.synthetic_part(), progress=progress)
            finally:
                opened.rig.close()
    except CalibrationFailedError as exc:           # (after the progress bar's last line)
        fail(str(exc), FAILED)
    except RigError as exc:
        fail(f"calibration failed: {exc}", FAILED)
    errors = write_calibration(out, cal, opened.truth)
    table = Table(title=escape(f"calibration -> {out}"))
    table.add_column("quantity")
    table.add_column("value", justify="right")
    pose = cal.pose.to_json()
    _row(table, "lenslets found", f"{len(cal.lattice.centres)} ({cal.lattice.rms_px:.3f} px lattice RMS)")
    _row(table, "array rotation / offset", f"{pose['rotation_deg']:.3f} deg / "
                                           f"({pose['offset_mm'][0]:.2f}, {pose['offset_mm'][1]:.2f}) mm")
    _row(table, "array tilt / pitch scale", f"({pose['tilt_deg'][0]:.3f}, {pose['tilt_deg'][1]:.3f}) deg / "
                                            f"{pose['scale']:.5f}")
    _row(table, "projector mapping RMS", f"{cal.projector_fit.rms_px:.3f} px")
    placement = cal.diagnostics.get("pose", {}).get("board_placement")
    if placement:
        _row(table, "board as measured vs as asked for", f"{placement['depth_mm']:+.2f} mm along its normal, "
                                                       f"{placement['tilt_deg']:.2f} deg")
    if errors is not None:
        _row(table, "error vs hidden truth: lenslet centres", f"{errors.lenslet_centre_rms_px:.3f} px")
        _row(table, "error vs hidden truth: projector mapping", f"{errors.projector_mapping_rms_px:.3f} px")
        _row(table, "error vs hidden truth: pose", f"{errors.pose_position_rms_mm:.2f} mm, "
                                                   f"{errors.pose_rotation_deg:.3f} deg")
        _row(table, "error vs hidden truth: responses", f"camera {errors.camera_response_error:.4f}, "
                                                        f"projector {errors.projector_response_error:.4f}")
    Console().print(table)
    Console().print(escape(f"wrote {out}, {out.parent / 'calibration_report.html'}"
                           + (f", {out.parent / 'calibration_errors.json'}" if errors is not None else "")),
                  soft_wrap=True)


def _parse_seeds(seeds: str) -> list[int]:
    try:
        seed_list = [int(s) for s in seeds.split(",") if s.strip()]
    except ValueError:
        fail(f"--seeds: expected comma-separated integers >= 0, got {seeds!r}")
    if not seed_list:
        fail("--seeds: give at least one seed")
    if any(s < 0 for s in seed_list):
        fail(f"--seeds: seeds are integers >= 0, got {seeds!r}")
    return seed_list


@calibrate_app.command("seeds", cls=_Command)
def calibrate_seeds_cmd(seeds: str = typer.Option("1,2,3,4,5", metavar="N,N,...",
                                                  help="Hidden-truth seeds (>= 0), comma-separated."),
                        scene_file: Optional[Path] = typer.Option(None, "--scene", metavar="SCENE.toml",
                                                                  help="Scene TOML (default: Fig. 4)."),
                        quick: bool = _flag("--quick", _QUICK_HELP),
                        out: Path = typer.Option(Path("out/calibration"), metavar="DIR", help="Output folder."),
                        cluster: Optional[str] = _cluster_option(),
                        workers: Optional[int] = _workers_option(),
                        max_memory: Optional[str] = _memory_option()) -> None:
    """Calibration accuracy over several hidden truths (writes calibration_errors.json and a Markdown table)."""
    from lftransfer.app.bench.calibration import calibration_seeds, markdown_table
    from lftransfer.app.report import write_json
    from lftransfer.calibration.rig import count_calibration_steps
    from lftransfer.imageio_utils import write_text

    from lftransfer.app.cluster import ClusterError

    seed_list = _parse_seeds(seeds)
    spec = _cluster_spec(cluster, workers)
    scene = _load(scene_file, quick)
    _check_before_work(scene, out_dir=out, max_memory=max_memory)
    steps = len(seed_list) if spec is not None else count_calibration_steps(scene) * len(seed_list)
    with _step_bar(steps) as progress:
        try:
            result = calibration_seeds(scene, seed_list, progress=progress, cluster=spec)
        except ClusterError as exc:
            fail(str(exc), FAILED)
    write_json(out / "calibration_errors.json", result.to_json())
    table = markdown_table(result)
    write_text(out / "calibration_errors.md", table)
    Console().print(escape(table))
    Console().print(escape(f"wrote {out / 'calibration_errors.json'} and {out / 'calibration_errors.md'}"))


@calibrate_app.command("lenslets", cls=_Command)
def calibrate_lenslets(image: Path = typer.Argument(..., metavar="IMAGE",
                                                    help="Image of a collimated on-axis source through the array "
                                                         "(8/16-bit PNG or TIFF, grey or colour)."),
                       lattice: str = typer.Option("hex", metavar="hex|rect", help="Lens lattice."),
                       kind: str = typer.Option("spots", metavar="spots|white",
                                                help="spots (collimator image) | white (white image)."),
                       out: Path = typer.Option(Path("centres.csv"), metavar="FILE.csv",
                                                help="CSV of lenslet centres (header x,y).")) -> None:
    """Find every lenslet's centre (sub-pixel spot or sub-image detection) and fit the lattice."""
    from lftransfer.app.paths import check_output_file
    from lftransfer.calibration.images import CalibrationImageError, read_image
    from lftransfer.calibration.lenslets import NoSpotsError, find_lenslet_centres, write_centres_csv

    if lattice not in ("hex", "rect"):
        fail(f"--lattice: expected hex or rect, got {lattice!r}")
    if kind not in ("spots", "white"):
        fail(f"--kind: expected spots or white, got {kind!r}")
    check_output_file(out, "--out", "centres.csv")
    try:
        fit = find_lenslet_centres(read_image(image), lattice, kind=kind)
    except (CalibrationImageError, NoSpotsError) as exc:
        fail(f"{image}: {exc}" if str(image) not in str(exc) else str(exc))
    write_centres_csv(out, fit)
    Console().print(escape(fit.summary()))
    Console().print(escape(f"wrote {len(fit.centres)} lenslet centres to {out}"))


@calibrate_app.command("latency", cls=_Command)
def calibrate_latency_cmd(rig_file: Path = typer.Argument(..., metavar="RIG.toml", help="Hardware rig file (TOML)."),
                          tries: int = typer.Option(20, min=1, metavar="N", help="Marker flashes to time (>= 1)."),
                          timeout_s: float = typer.Option(2.0, min=0.001, metavar="SECONDS",
                                                          help="Longest wait for one marker, seconds (> 0)."),
                          json_out: Optional[Path] = typer.Option(None, "--json", metavar="FILE.json",
                                                                  help="Also write the measurement as JSON.")) -> None:
    """Measure the projector-to-LF-camera delay (median and max over the tries) and write settle_s into the rig
    file."""
    from lftransfer.rig.base import RigError
    from lftransfer.rig.hardware import calibrate_latency

    if not rig_file.is_file():
        fail(f"{rig_file}: no such file")
    with Progress(TextColumn("[bold]{task.description:<40}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), console=console) as bar:
        task = bar.add_task("marker flashes", total=tries)
        try:
            result = calibrate_latency(rig_file, tries, timeout_s=timeout_s, operator=_operator(bar),
                                       progress=lambda i, n, d: bar.update(task, completed=i,
                                                                           description=f"last delay {1000 * d:.0f} ms"))
        except RigError as exc:
            bar.stop()
            fail(str(exc), FAILED)
    Console().print(escape(f"display -> capture delay: median {1000 * result.median_s:.1f} ms, max "
                           f"{1000 * result.max_s:.1f} ms over {len(result.samples)} tries; wrote projector.settle_s "
                           f"= {result.settle_s:.3f} s into {rig_file}"), soft_wrap=True)
    if result.frame_s > 0:
        Console().print(escape(f"the camera's frames come every {1000 * result.frame_s:.0f} ms: display-to-frame "
                               f"latency about {1000 * result.latency_s:.0f} ms (the median less half a frame)"),
                        soft_wrap=True)
    if json_out is not None:
        from lftransfer.imageio_utils import write_json

        write_json(json_out, result.to_json())


@calibrate_app.command("intrinsics", cls=_Command)
def calibrate_intrinsics_cmd(images: list[Path] = typer.Argument(..., metavar="IMAGE...",
                                                                 help="Chessboard photographs."),
                             pattern: str = typer.Option("9x6", metavar="COLSxROWS",
                                                         help="Inner corners, columns x rows."),
                             square_mm: float = typer.Option(..., "--square-mm", metavar="MM",
                                                             help="Chessboard square size, mm (> 0)."),
                             out: Path = typer.Option(Path("intrinsics.json"), metavar="FILE.json",
                                                      help="Output JSON.")) -> None:
    """Camera matrix and distortion (k1 k2 p1 p2 k3) by Zhang's method from chessboard photographs."""
    from lftransfer.app.paths import check_output_file
    from lftransfer.calibration.intrinsics import (IntrinsicsError, calibrate_intrinsics, parse_pattern,
                                                   write_intrinsics_json)

    if not square_mm > 0:
        fail(f"--square-mm: expected a positive size in millimetres, got {square_mm}")
    check_output_file(out, "--out", "intrinsics.json")
    try:
        intr = calibrate_intrinsics(images, parse_pattern(pattern), square_mm / 1000.0)
    except (IntrinsicsError, ValueError) as exc:
        fail(str(exc))
    write_intrinsics_json(out, intr)
    Console().print(f"{len(intr.used)} views used, {len(intr.skipped)} skipped; reprojection RMS {intr.rms_px:.3f} px")
    for name, why in intr.skipped.items():
        Console().print(escape(f"  skipped {name}: {why}"), soft_wrap=True)
    Console().print(escape(f"wrote {out}"))


from lftransfer.app.twin_cli import twin_app  # noqa: E402  (it uses the option helpers above)

app.add_typer(twin_app, name="twin")


def main() -> None:  # pragma: no cover
    logging.basicConfig(level=logging.WARNING)
    app()


if __name__ == "__main__":  # pragma: no cover
    main()

