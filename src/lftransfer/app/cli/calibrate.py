"""``lft calibrate``: every calibration step through the rig (``rig``, the default), one step on image files
(``lenslets``, ``intrinsics``), the projector's latency (``latency``) and calibration accuracy over hidden truths
(``seeds``)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from lftransfer.app.cli.common import (Group, check_before_work, cluster_spec, command, load, operator, progress_bar,
                                       rig_spec, row, step_bar, sub_app)
from lftransfer.app.cli.options import Cluster, MaxMemory, Quick, TruthArgs, Workers, option
from lftransfer.app.terminal import FAILED, fail

__all__ = ["calibrate_app"]


class _CalibrateGroup(Group):
    """``lft calibrate SCENE.toml ...`` is ``lft calibrate rig SCENE.toml ...``; other first words name a step."""

    def parse_args(self, ctx, args):
        if args and not args[0].startswith("-") and args[0] not in self.commands:
            args = ["rig", *args]
        return super().parse_args(ctx, args)


calibrate_app = sub_app(
    name="calibrate", cls=_CalibrateGroup, subcommand_metavar="SCENE.toml [OPTIONS] | COMMAND [ARGS]...",
    help="Calibrate the rig: lft calibrate SCENE.toml [--out FILE.json] [--quick] [--truth-seed N] [--exact-rig] "
         "[--rig SPEC] [--max-memory SIZE] (the same as lft calibrate rig SCENE.toml ...; see lft calibrate rig "
         "--help). Or run one step on image files (lenslets, intrinsics), measure the projector's latency, or "
         "measure calibration accuracy over hidden truths (seeds).")


@command(calibrate_app, "rig")
def calibrate_rig_cmd(scene_file: Annotated[Path, typer.Argument(metavar="SCENE.toml",
                                                                 help="Scene TOML file (its rig).")],
                      out: Annotated[Path, option("--out", metavar="FILE.json",
                                                  help="Calibration file to write (a file, not a folder); the "
                                                       "report and the errors go beside it.")
                                     ] = Path("calibration.json"),
                      quick: Quick = False, truth: TruthArgs = None,
                      rig: Annotated[str, option("--rig", metavar="SPEC", help=(
                          "Which rig: sim (simulated, default) | hardware:RIG.toml (a physical rig, or the device "
                          "twin)."))] = "sim",
                      max_memory: MaxMemory = None) -> None:
    """Run every calibration step through the rig; write the calibration file and its report.

    Also reachable as ``lft calibrate SCENE.toml``. Beside ``--out`` it writes ``calibration_report.html`` and,
    where the rig is simulated and knows its truth, ``calibration_errors.json``.
    """
    from lftransfer.runs.pipeline import RunOptions
    from lftransfer.runs.rigs import CalibrationFailedError, calibrate, open_rig, write_calibration
    from lftransfer.calibration.interfaces import count_steps
    from lftransfer.rig.base import RigError

    scene = load(scene_file, quick)
    options = RunOptions(truth_seed=truth.seed, rig=rig_spec(rig))
    check_before_work(scene, out_file=out, example="calibration.json", max_memory=max_memory)
    try:
        with step_bar(count_steps(scene)) as progress:
            opened = open_rig(scene, options, operator=operator(), interfaces=True)
            try:
                cal = calibrate(opened.rig, scene.synthetic_part(), progress=progress, rigs=opened.rigs)
            finally:
                opened.close()
    except CalibrationFailedError as exc:           # (after the progress bar's last line)
        fail(str(exc), FAILED)
    except RigError as exc:
        fail(f"calibration failed: {exc}", FAILED)
    errors = write_calibration(out, cal, opened.oracle)
    table = Table(title=escape(f"calibration -> {out}"))
    table.add_column("quantity")
    table.add_column("value", justify="right")
    if scene.interfaces:
        each = errors.errors if errors is not None else [None] * len(cal.names)
        for name, one, err in zip(cal.names, cal.interfaces, each):
            _rows(table, one, err, f"{name}: ")
    else:
        _rows(table, cal, errors, "")
    Console().print(table)
    Console().print(escape(f"wrote {out}, {out.parent / 'calibration_report.html'}"
                           + (f", {out.parent / 'calibration_errors.json'}" if errors is not None else "")),
                  soft_wrap=True)


def _rows(table: Table, cal, errors, tag: str) -> None:
    """The table's rows of one interface's calibration (``tag`` before each quantity) and its errors."""
    pose = cal.pose.to_json()
    row(table, f"{tag}lenslets found", f"{len(cal.lattice.centres)} ({cal.lattice.rms_px:.3f} px lattice RMS)")
    row(table, f"{tag}array rotation / offset", f"{pose['rotation_deg']:.3f} deg / "
                                                 f"({pose['offset_mm'][0]:.2f}, {pose['offset_mm'][1]:.2f}) mm")
    row(table, f"{tag}array tilt / pitch scale", f"({pose['tilt_deg'][0]:.3f}, {pose['tilt_deg'][1]:.3f}) deg / "
                                                  f"{pose['scale']:.5f}")
    row(table, f"{tag}projector mapping RMS", f"{cal.projector_fit.rms_px:.3f} px")
    placement = cal.diagnostics.get("pose", {}).get("board_placement")
    if placement:
        row(table, f"{tag}board as measured vs as asked for", f"{placement['depth_mm']:+.2f} mm along its normal, "
                                                             f"{placement['tilt_deg']:.2f} deg")
    if errors is not None:
        row(table, f"{tag}error vs hidden truth: lenslet centres", f"{errors.lenslet_centre_rms_px:.3f} px")
        row(table, f"{tag}error vs hidden truth: projector mapping", f"{errors.projector_mapping_rms_px:.3f} px")
        row(table, f"{tag}error vs hidden truth: pose", f"{errors.pose_position_rms_mm:.2f} mm, "
                                                         f"{errors.pose_rotation_deg:.3f} deg")
        row(table, f"{tag}error vs hidden truth: responses", f"camera {errors.camera_response_error:.4f}, "
                                                              f"projector {errors.projector_response_error:.4f}")


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


@command(calibrate_app, "seeds")
def calibrate_seeds_cmd(seeds: Annotated[str, option("--seeds", metavar="N,N,...",
                                                     help="Hidden-truth seeds (>= 0), comma-separated.")
                                         ] = "1,2,3,4,5",
                        scene_file: Annotated[Optional[Path], option("--scene", metavar="SCENE.toml",
                                                                     help="Scene TOML (default: Fig. 4).")] = None,
                        quick: Quick = False,
                        out: Annotated[Path, option("--out", metavar="DIR", help="Output folder.")
                                       ] = Path("out/calibration"),
                        cluster: Cluster = None, workers: Workers = None, max_memory: MaxMemory = None) -> None:
    """Calibration accuracy over several hidden truths (writes calibration_errors.json and a Markdown table)."""
    from lftransfer.runs.bench.calibration import calibration_seeds, markdown_table
    from lftransfer.reports.report import write_json
    from lftransfer.calibration.rig import count_calibration_steps
    from lftransfer.imageio_utils import write_text

    from lftransfer.runs.cluster import ClusterError

    seed_list = _parse_seeds(seeds)
    spec = cluster_spec(cluster, workers)
    scene = load(scene_file, quick)
    check_before_work(scene, out_dir=out, max_memory=max_memory)
    steps = len(seed_list) if spec is not None else count_calibration_steps(scene) * len(seed_list)
    with step_bar(steps) as progress:
        try:
            result = calibration_seeds(scene, seed_list, progress=progress, cluster=spec)
        except ClusterError as exc:
            fail(str(exc), FAILED)
    write_json(out / "calibration_errors.json", result.to_json())
    table = markdown_table(result)
    write_text(out / "calibration_errors.md", table)
    Console().print(escape(table))
    Console().print(escape(f"wrote {out / 'calibration_errors.json'} and {out / 'calibration_errors.md'}"))


@command(calibrate_app, "lenslets")
def calibrate_lenslets(image: Path = typer.Argument(..., metavar="IMAGE",
                                                    help="Image of a collimated on-axis source through the array "
                                                         "(8/16-bit PNG or TIFF, grey or colour)."),
                       lattice: str = typer.Option("hex", metavar="hex|rect", help="Lens lattice."),
                       kind: str = typer.Option("spots", metavar="spots|white",
                                                help="spots (collimator image) | white (white image)."),
                       out: Path = typer.Option(Path("centres.csv"), metavar="FILE.csv",
                                                help="CSV of lenslet centres (header x,y).")) -> None:
    """Find every lenslet's centre (sub-pixel spot or sub-image detection) and fit the lattice."""
    from lftransfer.runs.paths import check_output_file
    from lftransfer.imageio_utils import ImageReadError, read_image
    from lftransfer.calibration.lenslets import NoSpotsError, find_lenslet_centres, write_centres_csv

    if lattice not in ("hex", "rect"):
        fail(f"--lattice: expected hex or rect, got {lattice!r}")
    if kind not in ("spots", "white"):
        fail(f"--kind: expected spots or white, got {kind!r}")
    check_output_file(out, "--out", "centres.csv")
    try:
        fit = find_lenslet_centres(read_image(image), lattice, kind=kind)
    except (ImageReadError, NoSpotsError) as exc:
        fail(f"{image}: {exc}" if str(image) not in str(exc) else str(exc))
    write_centres_csv(out, fit)
    Console().print(escape(fit.summary()))
    Console().print(escape(f"wrote {len(fit.centres)} lenslet centres to {out}"))


@command(calibrate_app, "latency")
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
    with progress_bar(40) as bar:
        task = bar.add_task("marker flashes", total=tries)
        try:
            result = calibrate_latency(rig_file, tries, timeout_s=timeout_s, operator=operator(bar),
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


@command(calibrate_app, "intrinsics")
def calibrate_intrinsics_cmd(images: list[Path] = typer.Argument(..., metavar="IMAGE...",
                                                                 help="Chessboard photographs."),
                             pattern: str = typer.Option("9x6", metavar="COLSxROWS",
                                                         help="Inner corners, columns x rows."),
                             square_mm: float = typer.Option(..., "--square-mm", metavar="MM",
                                                             help="Chessboard square size, mm (> 0)."),
                             out: Path = typer.Option(Path("intrinsics.json"), metavar="FILE.json",
                                                      help="Output JSON.")) -> None:
    """Camera matrix and distortion (k1 k2 p1 p2 k3) by Zhang's method from chessboard photographs."""
    from lftransfer.runs.paths import check_output_file
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
