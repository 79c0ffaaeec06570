"""``lft twin``: the device twin as a separate process (``serve``) and the scoring of a run made through it
(``score``). The twin itself is :mod:`lftransfer.sim.twin`; this module is its face."""

from __future__ import annotations

import json
import signal
import threading
import time
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from lftransfer.app.cli.common import command, load, row, sub_app
from lftransfer.app.cli.options import Quick, TruthArgs, flag, setting_options
from lftransfer.app.terminal import FAILED, fail
from lftransfer.sim.twin.serve import VIEW_SPP

twin_app = sub_app(name="twin", help="The device twin: the simulated world in its own process behind real device "
                                     "interfaces (camera streams, a projector window on an X display, an operator "
                                     "endpoint), for --rig hardware:twin.toml; and the scoring of a run made through "
                                     "it.")

ScoreSettings = setting_options("gt_spp")


def _serve_table(twin, scene_file: Path, rig_file: Path, quick: bool, options) -> Table:
    """What ``lft twin serve`` serves, and how to use it."""
    from lftransfer.sim.twin import manifest_path

    table = Table(title=escape(f"lft twin serve {scene_file}"))
    table.add_column("")
    table.add_column("")
    files = ",".join(str(p) for p in twin.rig_files)
    several = len(twin.names) > 1
    row(table, "rig file" + ("s" if several else ""), f"{files} (manifest {manifest_path(rig_file)})")
    if several:
        row(table, "interfaces", ", ".join(twin.names) + ": each with its LF camera, projector and operator "
                                 "endpoint; one view camera")
    row(table, "streams", ", ".join(f"{twin.server.url}/{p}" for p in twin.cameras))
    row(table, "frames", f"LF camera {twin.world.info.lf_camera_bits}-bit codes, view camera linear 16-bit; "
                          "both as three stacked GRAY16LE planes in FFV1 (lossless; OpenCV's FFmpeg reader "
                          "returns 16-bit colour as 8 bits), planar = true in the rig file")
    row(table, "operator endpoint" + ("s" if several else ""),
        ", ".join(f"{twin.server.url}/{twin.operator_path(i)}" for i in range(len(twin.names))))
    row(table, "projector" + ("s" if several else ""), "missing (--projector-missing)" if options.projector_missing
        else f"display 0 of X display {twin.display}" + (", side by side (each rig file's projector.x)"
                                                          if several else ""))
    o = options
    row(table, "cameras", f"LF {o.lf_fps:g} fps, view {o.view_fps:g} fps; "
                          f"latency {o.latency_ms:g} +- {o.jitter_ms:g} ms"
         + (f"; drop {o.drop_rate:g}" if o.drop_rate else "")
         + (f"; {o.stop_camera} stops after {o.stop_after_s:g} s" if o.stop_after_s is not None else ""))
    row(table, "use it", f"lft run {scene_file}{' --quick' if quick else ''} --rig hardware:{files}")
    return table


@command(twin_app, "serve")
def serve_cmd(scene_file: Path = typer.Argument(..., metavar="SCENE.toml",
                                                help="Scene TOML file, or a built-in scene by name (fig4, ...)."),
              rig_file: Path = typer.Option(Path("twin.toml"), "--rig-file", metavar="RIG.toml",
                                            help="Rig file to write (its manifest RIG.json goes beside it)."),
              quick: Quick = False, truth: TruthArgs = None,
              display: Optional[str] = typer.Option(None, "--display", metavar=":N", help=(
                  "X display the projector window is shown on (its screen at least the projector's size); "
                  "default: the twin starts its own Xvfb of the projector's size.")),
              latency_ms: float = typer.Option(60.0, "--latency-ms", min=0, metavar="MS",
                                               help="Display-to-capture latency of both cameras, ms."),
              jitter_ms: float = typer.Option(5.0, "--jitter-ms", min=0, metavar="MS",
                                              help="Each frame's latency varies uniformly within +- this, ms."),
              lf_fps: float = typer.Option(7.0, "--lf-fps", min=0.1, metavar="FPS", help="LF camera frame rate."),
              view_fps: float = typer.Option(30.0, "--view-fps", min=0.1, metavar="FPS",
                                             help="View camera frame rate."),
              drop_rate: float = typer.Option(0.0, "--drop-rate", min=0.0, max=0.9, metavar="P",
                                              help="Probability that a frame is lost."),
              stop_after_s: Optional[float] = typer.Option(None, "--stop-after-s", min=0.0, metavar="S",
                                                           help="A camera's stream stops this long after the start."),
              stop_camera: str = typer.Option("lf", "--stop-camera", metavar="lf|view|both",
                                              help="Which camera --stop-after-s stops."),
              down_for_s: Optional[float] = typer.Option(None, "--down-for-s", min=0.0, metavar="S",
                                                         help="The stopped stream comes back after this long "
                                                              "(default: never)."),
              projector_missing: Annotated[bool, flag("--projector-missing", "The projector's display is missing: "
                                                                             "the rig file names an X display with "
                                                                             "no server.")] = False,
              port: int = typer.Option(0, "--port", min=0, max=65535, metavar="PORT",
                                       help="TCP port of the streams and endpoints (0: a free one)."),
              capture_spp: Optional[int] = typer.Option(None, "--capture-spp", min=1, metavar="N",
                                                        help="Rays per LF camera pixel (default: the simulated "
                                                             "rig's, as lft run)."),
              view_spp: int = typer.Option(VIEW_SPP, "--view-spp", min=1, metavar="N", help=(
                  "Samples per view camera pixel, rendered once per state (the quality the calibration's "
                  "photographs ask for).")),
              serve_for_s: Optional[float] = typer.Option(None, "--serve-for-s", min=0.0, metavar="S",
                                                          help="Stop serving after this long (default: until "
                                                               "Ctrl-C or SIGTERM).")) -> None:
    """Run the simulated world as a device: it watches the projector window on an X display, streams the LF and
    view cameras over HTTP (opened by OpenCV's VideoCapture) with a real device's timing and faults, and answers
    the rig's operator requests. Writes the rig file that --rig hardware:RIG.toml opens."""
    from lftransfer.sim.twin import Twin, TwinOptions

    if stop_camera not in ("lf", "view", "both"):
        fail(f"--stop-camera: expected lf, view or both, got {stop_camera!r}")
    if rig_file.exists() and rig_file.is_dir():
        fail(f"--rig-file {rig_file}: a folder; expected a file to write (e.g. twin.toml)")
    scene = load(scene_file, quick)
    options = TwinOptions(truth_seed=truth.seed, lf_fps=lf_fps, view_fps=view_fps,
                          latency_ms=latency_ms, jitter_ms=jitter_ms, drop_rate=drop_rate, stop_after_s=stop_after_s,
                          stop_camera=stop_camera, down_for_s=down_for_s, projector_missing=projector_missing,
                          display=display, port=port, capture_spp=capture_spp, view_spp=view_spp)
    ref = {"scene": str(scene_file.resolve()) if scene_file.exists() else str(scene_file), "quick": quick}
    console = Console()
    with console.status("starting the twin (its world, X display, cameras)"):
        try:
            twin = Twin(scene, rig_file, options, scene_ref=ref)
        except (RuntimeError, ValueError) as exc:
            fail(f"the twin could not start: {exc}", FAILED)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        console.print(_serve_table(twin, scene_file, rig_file, quick, options))
        console.print("serving; Ctrl-C stops the twin", highlight=False)
        stop.wait(serve_for_s)
        console.print(escape(json.dumps(twin.status())), soft_wrap=True, highlight=False)
    finally:
        twin.close()


@command(twin_app, "score")
def score_cmd(run_dir: Path = typer.Argument(..., metavar="RUN_DIR", help="A run folder of lft run / lft demo made "
                                                                           "with --rig hardware:TWIN.toml."),
              twin: Optional[Path] = typer.Option(None, "--twin", metavar="TWIN.json", help=(
                  "The twin's manifest (default: the one beside the rig file the run names).")),
              asked: ScoreSettings = None) -> None:
    """Render the ground truth of the twin's hidden world and write the run's metrics into its report.json, the
    same metrics lft run writes on the in-process rig (and the calibration's errors against the true rig)."""
    from lftransfer.runs.run_folder import VIEWS_FILE
    from lftransfer.reports.report import display_scale
    from lftransfer.imageio_utils import to_display, write_exr, write_json, write_png
    from lftransfer.sim.twin import manifest_path
    from lftransfer.settings import resolve_settings
    from lftransfer.sim.twin.score import SavedViews, score_views

    report_path = run_dir / "report.json"
    try:
        report = json.loads(report_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        fail(f"{report_path}: not a finished run's report ({exc})")
    if twin is None:
        rig = str(report.get("rig") or "")
        if not rig.startswith("hardware:"):
            fail(f"{report_path}: rig: the run was made on {rig!r}, not through a twin (hardware:TWIN.toml); "
                 "give --twin TWIN.json")
        twin = manifest_path(rig.split(":", 1)[1].split(",")[0])      # beside the (first interface's) rig file
    try:
        manifest = json.loads(twin.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        fail(f"{twin}: not a twin manifest ({exc})")
    if manifest.get("format") != "lftransfer-twin":
        fail(f"{twin}: format: expected 'lftransfer-twin', found {manifest.get('format')!r}")
    scene = load(Path(manifest["scene"]), bool(manifest.get("quick")))
    spp = resolve_settings(scene, asked.overrides()).gt_spp
    try:
        views = SavedViews.read(run_dir / VIEWS_FILE)
        t = time.perf_counter()
        with Console().status("rendering the ground truth"):
            scored = score_views(views, scene, manifest.get("truth_seed"), gt_spp=spp,
                                 calibration_file=run_dir / "calibration.json")
    except ValueError as exc:
        fail(str(exc))
    m = scored.metrics.to_json()
    keys = ("psnr_db", "psnr_db_direct_only", "psnr_objects_db", "psnr_objects_db_direct_only",
            "cross_transfer_rel_error", "gt_noise_psnr_db", "cross_gt_noise_rel", "cross_term_rel_size",
            "cross_by_side")
    report.update({k: m.get(k) for k in keys})
    report["undefined_metrics"] = {**report.get("undefined_metrics", {}), **m.get("undefined", {})}
    report["verification"] = f"against path-traced ground truth of the twin's world (lft twin score, {twin})"
    report["truth_seed"] = manifest.get("truth_seed")
    report["gt_spp"] = spp
    report.setdefault("timings_s", {})["twin_score"] = round(time.perf_counter() - t, 3)
    if scored.noisy is not None:
        report.setdefault("warnings", []).append(scored.noisy.message())
    if scored.calibration_errors is not None:
        report["calibration_errors"] = scored.calibration_errors.to_json()
        write_json(run_dir / "calibration_errors.json", report["calibration_errors"])
    gt = scored.ground_truth.image
    write_exr(run_dir / "ground_truth.exr", gt.astype("float32"))
    write_png(run_dir / "ground_truth.png", to_display(gt, display_scale(gt)))
    write_json(report_path, report)
    table = Table(title=escape(f"lft twin score {run_dir}"))
    table.add_column("metric")
    table.add_column("value", justify="right")
    for k in ("cross_transfer_rel_error", "psnr_objects_db", "psnr_db", "cross_gt_noise_rel"):
        v = report.get(k)
        row(table, k, "undefined" if v is None else f"{v:.4g}")
    if scored.calibration_errors is not None:
        e = scored.calibration_errors
        for name, each in zip(getattr(e, "names", ("",)), getattr(e, "errors", (e,))):   # several: each interface's
            of = f" ({name})" if name else ""
            row(table, f"calibration vs truth{of}: projector mapping", f"{each.projector_mapping_rms_px:.3f} px")
            row(table, f"calibration vs truth{of}: pose",
                f"{each.pose_position_rms_mm:.2f} mm, {each.pose_rotation_deg:.3f} deg")
    Console().print(table)
    Console().print(escape(f"wrote {report_path}, {run_dir / 'ground_truth.png'}"), soft_wrap=True)
