"""The ``lft`` command."""

from __future__ import annotations

import logging
from contextlib import contextmanager
from pathlib import Path
from typing import Optional

import typer
from typer.core import TyperGroup
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Light field transfer between real and synthetic objects.")
console = Console(stderr=True)


def _fail(message: str) -> None:
    console.print(f"[bold red]error:[/] {message}", soft_wrap=True, highlight=False)
    raise typer.Exit(code=2)


def _rig_spec(rig: str):
    from lftransfer.app.pipeline import RigSpec

    try:
        return RigSpec.parse(rig)
    except ValueError as exc:
        _fail(str(exc))


def _rig_options(truth_seed: int, exact_rig: bool, rig_model: str, calibration: Optional[Path],
                 rig: str = "sim") -> dict:
    from lftransfer.app.pipeline import RIG_MODELS

    if rig_model not in RIG_MODELS:
        _fail(f"--rig-model: expected one of {', '.join(RIG_MODELS)}, got {rig_model!r}")
    if calibration is not None and not calibration.is_file():
        _fail(f"--calibration: {calibration}: no such file")
    spec = _rig_spec(rig)
    if rig_model == "oracle" and spec.kind != "sim":
        _fail("--rig-model oracle: only the simulated rig (--rig sim) knows its truth")
    return {"truth_seed": None if exact_rig else truth_seed, "rig_model": rig_model, "calibration": calibration,
            "rig": spec}


def _operator(bar: Progress | None = None):
    """The operator callback of a physical rig: show the instruction, wait for Enter (progress bar paused)."""
    import sys

    from rich.markup import escape

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


_TRUTH_SEED_HELP = "Seed of the simulated rig's hidden truth (how the rig as built differs from the rig file)."
_EXACT_HELP = "Build the simulated rig exactly as the rig file says (no hidden deviations)."
_MODEL_HELP = "What the pipeline knows of the rig: calibrated (calibrate first) | nominal (rig file) | oracle."
_CAL_HELP = "Use this calibration file (from `lft calibrate`) instead of calibrating."
_RIG_HELP = "Which rig: sim (simulated, default) | hardware:RIG.toml (a physical rig) | replay:DIR (a recording)."


def _run(scene, out: Path, bounces: int, lighting_model: Optional[str], compare: bool, gt_spp: Optional[int],
         use_cache: bool, renderer: str = "auto", rig: dict | None = None, record: Optional[Path] = None) -> dict:
    from lftransfer.calibration.rig import CalibrationFileError
    from lftransfer.app.pipeline import RunOptions, count_run_steps, run_scene
    from lftransfer.rig.base import RigError

    options = RunOptions(bounces=bounces, lighting_model=lighting_model,
                         compare_models=("area", "point") if compare else (), gt_spp=gt_spp, use_cache=use_cache,
                         renderer=renderer, record=record, **(rig or {}))
    total = count_run_steps(scene, options)
    with Progress(TextColumn("[bold]{task.description:<58}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), console=console, transient=False) as bar:
        task = bar.add_task("starting", total=total)

        def progress(msg: str, done: int) -> None:
            bar.update(task, description=msg[:58], completed=min(done, total))

        try:
            report = run_scene(scene, out, options, progress=progress, operator=_operator(bar))
        except (CalibrationFileError, RigError) as exc:
            bar.stop()
            _fail(f"{exc} (what was written so far is in {out}; {out / 'status.json'} says where it stopped)")
        bar.update(task, description="done", completed=total)
    _summary(report, out)
    return report


def _summary(report: dict, out: Path) -> None:
    table = Table(title=f"light field transfer -> {out}")
    table.add_column("metric")
    table.add_column("value", justify="right")
    table.add_row("rig", str(report["rig"]))
    table.add_row("verification", str(report["verification"]))
    for key in ("psnr_db", "psnr_db_direct_only", "cross_transfer_rel_error", "gt_noise_psnr_db",
                "cross_gt_noise_rel"):
        if report.get(key) is not None:
            table.add_row(key, f"{report[key]:.4g}")
    for name, m in report["by_lighting_model"].items():
        if m.get("cross_transfer_rel_error") is not None:
            table.add_row(f"cross error, {name} model", f"{m['cross_transfer_rel_error']:.4g}")
    for b in report["bounces"]:
        table.add_row(f"bounce {b['index']} energy real / synthetic", f"{b['real_energy']:.3g} / {b['synthetic_energy']:.3g}")
    table.add_row("rig model", str(report["rig_model"]))
    errors = report.get("calibration_errors") or {}
    if "lenslet_centre_rms_px" in errors:
        table.add_row("calibration: lenslet centres RMS", f"{errors['lenslet_centre_rms_px']:.3f} px")
    if "pose_position_rms_mm" in errors:
        table.add_row("calibration: pose error", f"{errors['pose_position_rms_mm']:.2f} mm, "
                                                 f"{errors['pose_rotation_deg']:.3f} deg")
    table.add_row("total time", f"{report['timings_s']['total']:.1f} s")
    Console().print(table)


def _check_renderer(renderer: str) -> None:
    if renderer not in ("auto", "fast", "exact"):
        _fail(f"--renderer: expected one of auto, fast, exact, got {renderer!r}")


def _load(path: Path):
    from lftransfer.scenes import SceneError, load_scene

    try:
        return load_scene(path)
    except SceneError as exc:
        _fail(str(exc))


@app.command()
def demo(out: Path = typer.Option(Path("out/demo"), help="Output folder."),
         quick: bool = typer.Option(False, "--quick", help="Quarter resolution, fewer samples (seconds, not minutes)."),
         bounces: int = typer.Option(2, min=0, help="Number of bounces."),
         no_cache: bool = typer.Option(False, "--no-cache", help="Render the ground truth again."),
         renderer: str = typer.Option("auto", help="Synthetic renderer: auto | fast | exact."),
         truth_seed: int = typer.Option(0, help=_TRUTH_SEED_HELP),
         exact_rig: bool = typer.Option(False, "--exact-rig", help=_EXACT_HELP),
         rig_model: str = typer.Option("calibrated", help=_MODEL_HELP),
         calibration: Optional[Path] = typer.Option(None, help=_CAL_HELP),
         rig: str = typer.Option("sim", help=_RIG_HELP)) -> None:
    """Run the paper's Fig. 4 scene (10 x 12 hexagonal lenslets), by default on the simulated rig: calibrate,
    transfer, check against ground truth."""
    from lftransfer.app.pipeline import quick_scene
    from lftransfer.scenes import builtin_scene

    scene = _load(builtin_scene("fig4"))
    if quick:
        scene = quick_scene(scene)
    _check_renderer(renderer)
    _run(scene, out, bounces, None, True, None, not no_cache, renderer,
         _rig_options(truth_seed, exact_rig, rig_model, calibration, rig))


@app.command()
def run(scene_file: Path = typer.Argument(..., help="Scene TOML file."),
        bounces: int = typer.Option(2, min=0, help="Number of bounces."),
        out: Path = typer.Option(Path("out/run"), help="Output folder."),
        lighting_model: Optional[str] = typer.Option(None, help="area | point | prefiltered (default: the scene's)."),
        compare: bool = typer.Option(False, "--compare-models", help="Also measure the other lighting model."),
        gt_spp: Optional[int] = typer.Option(None, help="Ground-truth samples per pixel."),
        quick: bool = typer.Option(False, "--quick", help="Quarter resolution."),
        no_cache: bool = typer.Option(False, "--no-cache", help="Render the ground truth again."),
        renderer: str = typer.Option("auto", help="Synthetic renderer: auto | fast | exact."),
        truth_seed: int = typer.Option(0, help=_TRUTH_SEED_HELP),
        exact_rig: bool = typer.Option(False, "--exact-rig", help=_EXACT_HELP),
        rig_model: str = typer.Option("calibrated", help=_MODEL_HELP),
        calibration: Optional[Path] = typer.Option(None, help=_CAL_HELP),
        rig: str = typer.Option("sim", help=_RIG_HELP)) -> None:
    """Run light field transfer on any scene file with a rig (calibrating it first)."""
    from lftransfer.app.pipeline import quick_scene
    from lftransfer.render.lights import LIGHTING_MODELS

    if lighting_model is not None and lighting_model not in LIGHTING_MODELS:
        _fail(f"--lighting-model: expected one of {', '.join(LIGHTING_MODELS)}, got {lighting_model!r}")
    if not scene_file.exists():
        _fail(f"{scene_file}: no such file")
    scene = _load(scene_file)
    if quick:
        scene = quick_scene(scene)
    _check_renderer(renderer)
    _run(scene, out, bounces, lighting_model, compare, gt_spp, not no_cache, renderer,
         _rig_options(truth_seed, exact_rig, rig_model, calibration, rig))


@app.command()
def record(scene_file: Path = typer.Argument(..., help="Scene TOML file."),
           out: Path = typer.Option(..., "--out", help="Session folder: the recording, and the run's outputs in run/."),
           rig: str = typer.Option("sim", help="Which rig to record: sim | hardware:RIG.toml."),
           bounces: int = typer.Option(2, min=0, help="Number of bounces."),
           quick: bool = typer.Option(False, "--quick", help="Quarter resolution."),
           renderer: str = typer.Option("auto", help="Synthetic renderer: auto | fast | exact."),
           truth_seed: int = typer.Option(0, help=_TRUTH_SEED_HELP),
           exact_rig: bool = typer.Option(False, "--exact-rig", help=_EXACT_HELP),
           calibration: Optional[Path] = typer.Option(None, help=_CAL_HELP)) -> None:
    """Calibrate and run transfer on a rig while storing every request and image it answers (replay it with
    ``lft run SCENE.toml --rig replay:SESSION``)."""
    from lftransfer.app.pipeline import quick_scene

    if rig.startswith("replay"):
        _fail("--rig: a recording is recorded already; record from sim or hardware:RIG.toml")
    if not scene_file.exists():
        _fail(f"{scene_file}: no such file")
    if (out / "manifest.json").exists():
        _fail(f"--out {out}: holds a recording already; choose an empty folder")
    scene = _load(scene_file)
    if quick:
        scene = quick_scene(scene)
    _check_renderer(renderer)
    _run(scene, out / "run", bounces, None, False, None, True, renderer,
         _rig_options(truth_seed, exact_rig, "calibrated", calibration, rig), record=out)
    Console().print(f"recorded the session into {out} (replay: lft run {scene_file} --rig replay:{out}"
                    f"{' --quick' if quick else ''} --bounces {bounces})")


@app.command()
def bench(scene_file: Optional[Path] = typer.Option(None, "--scene", help="Scene TOML (default: Fig. 4)."),
          json_out: Optional[Path] = typer.Option(None, "--json", help="Write the results as JSON here."),
          iterations: int = typer.Option(10, min=1, help="Timed pipeline iterations."),
          lighting_model: str = typer.Option("area", help="Lighting model of the fast path."),
          peer: bool = typer.Option(True, help="Also time Mitsuba's path integrator on the same job."),
          quick: bool = typer.Option(False, "--quick", help="Quarter resolution.")) -> None:
    """Time one light field transfer iteration (decode, relight, render, encode, view, composite)."""
    from lftransfer.app.bench.iteration import BenchSettings, run_bench
    from lftransfer.app.pipeline import quick_scene
    from lftransfer.render.lights import LIGHTING_MODELS
    from lftransfer.app.report import write_json
    from lftransfer.scenes import builtin_scene

    if lighting_model not in LIGHTING_MODELS:
        _fail(f"--lighting-model: expected one of {', '.join(LIGHTING_MODELS)}, got {lighting_model!r}")
    if scene_file is not None and not scene_file.exists():
        _fail(f"{scene_file}: no such file")
    scene = _load(scene_file or builtin_scene("fig4"))
    if quick:
        scene = quick_scene(scene)
    with Progress(TextColumn("[bold]{task.description:<70}"), TimeElapsedColumn(), console=console) as bar:
        task = bar.add_task("starting", total=None)
        result = run_bench(scene, BenchSettings(iterations=iterations, lighting_model=lighting_model, peer=peer),
                           progress=lambda msg: bar.update(task, description=msg[:70]))
    table = Table(title="light field transfer iteration")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_row("pipeline iteration (median)", f"{result['pipeline_iteration_ms']:.1f} ms")
    for stage, t in result["stages_ms"].items():
        table.add_row(f"  {stage}", f"{t['median']:.1f} ms")
    table.add_row("capture (rig, not in the iteration)", f"{result['capture_ms']:.0f} ms")
    table.add_row("fast vs exact composite PSNR", f"{result['fast_vs_exact_psnr_db']:.1f} dB")
    if "peer_ratio" in result:
        table.add_row("peer (Mitsuba path, projectors)", f"{result['peer_ms']:.0f} ms at {result['peer_spp']} spp")
        table.add_row("peer ratio", f"{result['peer_ratio']:.0f}x")
    table.add_row("variant, peak RSS", f"{result['variant']}, {result['peak_rss_mb']:.0f} MB")
    Console().print(table)
    if json_out is not None:
        write_json(json_out, result)


@contextmanager
def _step_bar(total: int):
    """A progress bar that advances by one on every message; yields the callback."""
    with Progress(TextColumn("[bold]{task.description:<58}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), console=console) as bar:
        task = bar.add_task("starting", total=total)
        done = [0]

        def progress(msg: str) -> None:
            done[0] += 1
            bar.update(task, description=msg[:58], completed=min(done[0], total))

        yield progress
        bar.update(task, description="done", completed=total)


class _CalibrateGroup(TyperGroup):
    """``lft calibrate SCENE.toml ...`` is ``lft calibrate rig SCENE.toml ...``; other first words name a step."""

    def parse_args(self, ctx, args):
        if args and not args[0].startswith("-") and args[0] not in self.commands:
            args = ["rig", *args]
        return super().parse_args(ctx, args)


calibrate_app = typer.Typer(cls=_CalibrateGroup, no_args_is_help=True,
                            help="Calibrate the rig (lft calibrate SCENE.toml), or run one step on image files.")
app.add_typer(calibrate_app, name="calibrate")


@calibrate_app.command("rig")
def calibrate_rig_cmd(scene_file: Path = typer.Argument(..., help="Scene TOML file (its rig)."),
                      out: Path = typer.Option(Path("calibration.json"), help="Calibration file to write."),
                      quick: bool = typer.Option(False, "--quick", help="Quarter resolution."),
                      truth_seed: int = typer.Option(0, help=_TRUTH_SEED_HELP),
                      exact_rig: bool = typer.Option(False, "--exact-rig", help=_EXACT_HELP),
                      rig: str = typer.Option("sim", help=_RIG_HELP)) -> None:
    """Run every calibration step through the rig; write the calibration file and its report.

    Also reachable as ``lft calibrate SCENE.toml``. Beside ``--out`` it writes ``calibration_report.html`` and,
    where the rig is simulated and knows its truth, ``calibration_errors.json``.
    """
    from lftransfer.calibration.rig import calibrate_rig, count_calibration_steps
    from lftransfer.app.pipeline import RunOptions, open_rig, quick_scene, write_calibration
    from lftransfer.rig.base import RigError

    if not scene_file.exists():
        _fail(f"{scene_file}: no such file")
    scene = _load(scene_file)
    if quick:
        scene = quick_scene(scene)
    options = RunOptions(truth_seed=None if exact_rig else truth_seed, rig=_rig_spec(rig))
    with _step_bar(count_calibration_steps(scene)) as progress:
        opened = open_rig(scene, options, operator=_operator())
        try:
            cal = calibrate_rig(opened.rig, scene.synthetic_part(), progress=progress)
        except (ValueError, RigError) as exc:
            _fail(f"calibration failed: {exc}")
        finally:
            opened.rig.close()
    errors = write_calibration(out, cal, opened.truth) or {}
    table = Table(title=f"calibration -> {out}")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    pose = cal.pose.to_json()
    table.add_row("lenslets found", f"{len(cal.lattice.centres)} ({cal.lattice.rms_px:.3f} px lattice RMS)")
    table.add_row("array rotation / offset", f"{pose['rotation_deg']:.3f} deg / "
                                             f"({pose['offset_mm'][0]:.2f}, {pose['offset_mm'][1]:.2f}) mm")
    table.add_row("array tilt / pitch scale", f"({pose['tilt_deg'][0]:.3f}, {pose['tilt_deg'][1]:.3f}) deg / "
                                              f"{pose['scale']:.5f}")
    table.add_row("projector mapping RMS", f"{cal.projector_fit.rms_px:.3f} px")
    placement = cal.diagnostics.get("pose", {}).get("board_placement")
    if placement:
        table.add_row("board as measured vs as asked for", f"{placement['depth_mm']:+.2f} mm along its normal, "
                                                         f"{placement['tilt_deg']:.2f} deg")
    if errors:
        table.add_row("error vs hidden truth: lenslet centres", f"{errors['lenslet_centre_rms_px']:.3f} px")
        table.add_row("error vs hidden truth: projector mapping", f"{errors['projector_mapping_rms_px']:.3f} px")
        table.add_row("error vs hidden truth: pose", f"{errors['pose_position_rms_mm']:.2f} mm, "
                                                     f"{errors['pose_rotation_deg']:.3f} deg")
        table.add_row("error vs hidden truth: responses", f"camera {errors['camera_response_error']:.4f}, "
                                                          f"projector {errors['projector_response_error']:.4f}")
    Console().print(table)
    Console().print(f"wrote {out}, {out.parent / 'calibration_report.html'}"
                    + (f", {out.parent / 'calibration_errors.json'}" if errors else ""))


@calibrate_app.command("seeds")
def calibrate_seeds_cmd(seeds: str = typer.Option("1,2,3,4,5", help="Hidden-truth seeds, comma-separated."),
                        scene_file: Optional[Path] = typer.Option(None, "--scene", help="Scene TOML (default: Fig. 4)."),
                        quick: bool = typer.Option(False, "--quick", help="Quarter resolution."),
                        out: Path = typer.Option(Path("out/calibration"), help="Output folder.")) -> None:
    """Calibration accuracy over several hidden truths (writes calibration_errors.json and a Markdown table)."""
    from lftransfer.app.bench.calibration import calibration_seeds, markdown_table
    from lftransfer.calibration.rig import count_calibration_steps
    from lftransfer.app.pipeline import quick_scene
    from lftransfer.app.report import write_json
    from lftransfer.scenes import builtin_scene

    try:
        seed_list = [int(s) for s in seeds.split(",") if s.strip()]
    except ValueError:
        _fail(f"--seeds: expected comma-separated integers, got {seeds!r}")
    if not seed_list:
        _fail("--seeds: give at least one seed")
    if scene_file is not None and not scene_file.exists():
        _fail(f"{scene_file}: no such file")
    scene = _load(scene_file or builtin_scene("fig4"))
    if quick:
        scene = quick_scene(scene)
    with _step_bar(count_calibration_steps(scene) * len(seed_list)) as progress:
        result = calibration_seeds(scene, seed_list, progress=progress)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "calibration_errors.json", result)
    table = markdown_table(result)
    (out / "calibration_errors.md").write_text(table)
    Console().print(table)
    Console().print(f"wrote {out / 'calibration_errors.json'} and {out / 'calibration_errors.md'}")


@calibrate_app.command("lenslets")
def calibrate_lenslets(image: Path = typer.Argument(..., help="Image of a collimated on-axis source through the array "
                                                          "(8/16-bit PNG or TIFF, grey or colour)."),
                       lattice: str = typer.Option("hex", help="hex | rect"),
                       kind: str = typer.Option("spots", help="spots (collimator image) | white (white image)"),
                       out: Path = typer.Option(Path("centres.csv"), help="CSV of lenslet centres (header x,y).")) -> None:
    """Find every lenslet's centre (sub-pixel spot or sub-image detection) and fit the lattice."""
    from lftransfer.calibration.images import CalibrationImageError, read_image
    from lftransfer.calibration.lenslets import NoSpotsError, find_lenslet_centres, write_centres_csv

    if lattice not in ("hex", "rect"):
        _fail(f"--lattice: expected hex or rect, got {lattice!r}")
    if kind not in ("spots", "white"):
        _fail(f"--kind: expected spots or white, got {kind!r}")
    try:
        fit = find_lenslet_centres(read_image(image), lattice, kind=kind)
    except (CalibrationImageError, NoSpotsError) as exc:
        _fail(f"{image}: {exc}" if str(image) not in str(exc) else str(exc))
    write_centres_csv(out, fit)
    Console().print(fit.summary())
    Console().print(f"wrote {len(fit.centres)} lenslet centres to {out}")


@calibrate_app.command("latency")
def calibrate_latency_cmd(rig_file: Path = typer.Argument(..., help="Hardware rig file (TOML)."),
                          tries: int = typer.Option(20, min=1, help="Marker flashes to time."),
                          timeout_s: float = typer.Option(2.0, help="Longest wait for one marker, seconds.")) -> None:
    """Measure the projector-to-LF-camera delay (median and max over the tries) and write settle_s into the rig
    file."""
    from lftransfer.rig.base import RigError
    from lftransfer.rig.hardware import calibrate_latency
    from lftransfer.rig.hardware.config import RigFileError

    if not rig_file.is_file():
        _fail(f"{rig_file}: no such file")
    with Progress(TextColumn("[bold]{task.description:<40}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), console=console) as bar:
        task = bar.add_task("marker flashes", total=tries)
        try:
            result = calibrate_latency(rig_file, tries, timeout_s=timeout_s, operator=_operator(bar),
                                       progress=lambda i, n, d: bar.update(task, completed=i,
                                                                           description=f"last delay {1000 * d:.0f} ms"))
        except (RigError, RigFileError) as exc:
            bar.stop()
            _fail(str(exc))
    Console().print(f"display -> capture delay: median {1000 * result.median_s:.1f} ms, max {1000 * result.max_s:.1f} ms "
                    f"over {len(result.samples)} tries; wrote projector.settle_s = {result.settle_s:.3f} s into {rig_file}")


@calibrate_app.command("intrinsics")
def calibrate_intrinsics_cmd(images: list[Path] = typer.Argument(..., help="Chessboard photographs."),
                             pattern: str = typer.Option("9x6", help="Inner corners, columns x rows."),
                             square_mm: float = typer.Option(..., "--square-mm", help="Chessboard square size, mm."),
                             out: Path = typer.Option(Path("intrinsics.json"), help="Output JSON.")) -> None:
    """Camera matrix and distortion (k1 k2 p1 p2 k3) by Zhang's method from chessboard photographs."""
    from lftransfer.calibration.intrinsics import (IntrinsicsError, calibrate_intrinsics, parse_pattern,
                                                   write_intrinsics_json)

    if not square_mm > 0:
        _fail(f"--square-mm: expected a positive size in millimetres, got {square_mm}")
    try:
        intr = calibrate_intrinsics(images, parse_pattern(pattern), square_mm / 1000.0)
    except (IntrinsicsError, ValueError) as exc:
        _fail(str(exc))
    write_intrinsics_json(out, intr)
    Console().print(f"{len(intr.used)} views used, {len(intr.skipped)} skipped; reprojection RMS {intr.rms_px:.3f} px")
    for name, why in intr.skipped.items():
        Console().print(f"  skipped {name}: {why}")
    Console().print(f"wrote {out}")


def main() -> None:  # pragma: no cover
    logging.basicConfig(level=logging.WARNING)
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
