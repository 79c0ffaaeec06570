"""``lft render`` (a sequence over the scene's animation) and ``lft live`` (the live loop on a page)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import TextColumn
from rich.table import Table

from lftransfer import choices
from lftransfer.app.cli.common import (calibrates, check_before_work, cluster_spec, command, ending_cleanly, load,
                                       progress_bar, rig_options, row)
from lftransfer.app.cli.options import (Cluster, MaxMemory, NoCache, NoFloor, OutDir, Quick, RigArgs, SceneArg,
                                        TruthArgs, Workers, choice_check, flag, metavar, option, setting_options)
from lftransfer.app.terminal import FAILED, console, fail, warn

__all__ = ["register"]

SIMULATOR_SETTINGS = ("simulator", "simulator_threads", "simulator_nice", "simulator_share", "renderer_threads")
LiveSettings = setting_options("renderer", *SIMULATOR_SETTINGS)
RenderSettings = setting_options("bounces", "gt_spp", "renderer", "composite", "direct_light", "quiet_reference",
                                 *SIMULATOR_SETTINGS)


def _sequence_table(report: dict, out: Path, mode: str, check) -> None:
    """A rendered sequence's summary as a table on stdout, its warnings first."""
    summary = report["summary"]
    table = Table(title=escape(f"{mode} sequence -> {out}"))
    table.add_column("")
    table.add_column("value", justify="right")
    row(table, "summary.frames", str(summary["frames"]))
    if report.get("cluster"):
        c = report["cluster"]
        row(table, "cluster", f"{c['workers']} workers on {c['address']} ({c['cpus']:g} CPUs, {c['gpus']:g} GPUs)")
    row(table, "summary.median_frame_s (transfer_fps)", f"{summary['median_frame_s']:.3g} s ({summary['transfer_fps']:.3g} frames/s)")
    if report.get("loop"):
        row(table, "loop", report["loop"])
    if "capture_behind_s_median" in summary:
        row(table, "summary.capture_behind_s_median / _max (captures_used)",
            f"median {summary['capture_behind_s_median']:.3g} s, at most {summary['capture_behind_s_max']:.3g} s "
            f"({summary['captures_used']} captures for {summary['frames']} frames)")
    if "psnr_objects_db_min" in summary:
        row(table, "summary.psnr_objects_db_min .. _max",
            f"{summary['psnr_objects_db_min']:.2f} .. {summary['psnr_objects_db_max']:.2f} dB")
    if "cross_transfer_rel_error_min" in summary:
        row(table, "summary.cross_transfer_rel_error_min .. _max",
            f"{summary['cross_transfer_rel_error_min']:.3f} .. {summary['cross_transfer_rel_error_max']:.3f}"
            + (f" (ground truth's own noise on it: up to {summary['cross_gt_noise_rel_max']:.3f})"
               if summary.get("cross_gt_noise_rel_max") is not None else ""))
    if "transfer_over_floor_min" in summary:
        row(table, "summary.fidelity_floor_min .. _max",
            _range(summary, "fidelity_floor") + f" (real {_range(summary, 'real_floor')}, synthetic "
            f"{_range(summary, 'synthetic_floor')}); the frames {_range(summary, 'transfer_over_floor', '.2f')} "
            "x the floor")
    if "references" in summary:
        row(table, "summary.reference_spp_min .. _max",
            f"{_range(summary, 'reference_spp', '.0f')} samples per pixel, noise "
            f"{_range(summary, 'reference_noise_over_error', '.2f')} of the error; target met in "
            f"{summary['references_met']} of {summary['references']} frames")
    effect = check.effect if check is not None else None
    if effect is not None:
        for name, worst in effect.worst_relative_error().items():
            trend = effect.trend()[name]
            row(table, f"effect.{name} against ground truth",
                "undefined" if worst is None else f"worst {100 * worst:.0f} % off"
                + ("" if trend is None else f", same trend in {100 * trend:.0f} % of steps"))
        row(table, "effect curve", f"{out / 'effect.png'}")
    row(table, "rig_model", report["rig_model"])
    if "stale_captures" in summary:
        row(table, "summary.stale_captures", str(summary["stale_captures"]))
    for note in report["approximations"]:
        row(table, "approximations", note)
    row(table, "videos", f"{out / 'composite.mp4'}, {out / 'bounces.mp4'}")
    for line in report.get("warnings", []):
        warn(line)
    Console().print(table)


def _range(summary: dict, key: str, spec: str = ".3f") -> str:
    """``min .. max`` of ``key`` in a sequence's summary (one number where they agree; - where missing)."""
    lo, hi = summary.get(f"{key}_min"), summary.get(f"{key}_max")
    if lo is None or hi is None:
        return "-"
    a, b = format(lo, spec), format(hi, spec)
    return a if a == b else f"{a} .. {b}"


def live(scene_file: SceneArg,
         port: Annotated[int, option("--port", min=1, max=65535, metavar="PORT",
                                     help="Port of the page on localhost.")] = 8080,
         out: Annotated[Path, option("--out", metavar="DIR", help=(
             "Session folder: the calibration the session uses (calibration.json, its report and errors), written "
             "at start-up, and what 'save' writes (frames and scenes)."))] = Path("out/live"),
         quick: Quick = False,
         sync: Annotated[bool, flag("--sync", "One capture inside every frame (for measurement); default: "
                                              "captures on their own thread at the devices' rate, frames at the "
                                              "renderer's rate with the newest capture.")] = False,
         truth: TruthArgs = None, rig: RigArgs = None, asked: LiveSettings = None) -> None:
    """Run the live loop and show it on a page at http://127.0.0.1:PORT/ until Ctrl-C: the composite and its
    layers, the light field images, the time of every stage, the capture rate, each frame's capture age and
    the motion-to-composite latency, and, on demand, the layers of each bounce with their display gains, an
    A/B comparison with the ground truth (simulated rig) and a recording to MP4; move and edit the synthetic
    objects (and the real ones on the simulated rig), change the bounces and the lighting model, pause, step,
    reset, save."""
    try:
        from lftransfer.app.viewer.server import serve
    except ImportError as exc:
        fail(f"lft live needs the viewer's packages ({exc.name} is missing): pip install 'lftransfer[viewer]'")
    from lftransfer.app.viewer.command import open_session

    scene = load(scene_file, quick)
    rig_opts = rig_options(scene, truth, rig)
    check_before_work(scene, out_dir=out, calibrate=calibrates(scene, rig_opts))
    with console.status("setting up the rig (calibrating takes minutes at full resolution)") as status:
        session = open_session(scene, rig=str(rig_opts["rig"]), rig_model=rig.rig_model,
                               calibration=rig.calibration, recalibrate=rig.recalibrate,
                               truth_seed=rig_opts["truth_seed"], out=out,
                               settings=asked.overrides(), loop="sync" if sync else choices.DEFAULT_LIVE_LOOP,
                               progress=lambda msg: status.update(escape(msg[:70])),
                               warn=warn)
    console.print(f"lft live: open http://127.0.0.1:{port}/ (Ctrl-C stops)")
    serve(session, port=port)
    if session.failed is not None:
        fail(session.failed, FAILED)
    console.print("lft live: stopped")


def _render_with_progress(scene, out: Path, options, seq) -> tuple[dict, object]:
    """Render the sequence and check its exchange under a progress bar (frames per second, each frame's PSNR); a
    failure is one line with its exit code, naming where the finished frames are."""
    from lftransfer.calibration.rig import CalibrationFileError
    from lftransfer.rig.base import RigError
    from lftransfer.runs.cluster import ClusterError
    from lftransfer.runs.effects import verify_exchange
    from lftransfer.runs.rigs import CalibrationFailedError
    from lftransfer.runs.sequence import SequenceError, render_sequence

    status = out / "status.json"
    with progress_bar(40, TextColumn("{task.fields[rate]}")) as bar:
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

        with ending_cleanly(bar, interrupted=f"interrupted; the finished frames are in {out}; --resume continues",
                            refused=(SequenceError, CalibrationFileError),
                            failed=(RigError, CalibrationFailedError, ClusterError),
                            where=f"the finished frames are in {out}; {status} says where it stopped"):
            report = render_sequence(scene, out, options, seq, progress=progress, step=step)
            check = verify_exchange(scene, out, options, report, step=step)
    return report, check


def render_cmd(scene_file: SceneArg, out: OutDir = Path("out/render"),
               frames: Annotated[Optional[int], option(
                   "--frames", min=1, metavar="N",
                   help="Frames to render (default: every frame of the scene's [animation]; a still scene: 8 "
                        "live frames or 1 converged frame).")] = None,
               mode: Annotated[str, option(
                   "--mode", metavar="live|converged",
                   help="live: the paper's loop, one capture and one render per frame, bounces accumulating "
                        "over frames | converged: every frame an independent N-bounce transfer.")] = "live",
               loop: Annotated[str, option(
                   "--loop", metavar=metavar(choices.LiveLoop), callback=choice_check("--loop", choices.LiveLoop),
                   help="Live mode: sync: one capture inside every frame (the same frames on every run) | "
                        "decoupled: captures on their own thread at the rig's rate, every frame rendered with "
                        "the newest (the report says how far behind each frame's capture was).")
               ] = choices.DEFAULT_SEQUENCE_LOOP,
               resume: Annotated[bool, flag("--resume", "Continue after the last finished frame in DIR (same "
                                                        "settings).")] = False,
               verify_every: Annotated[int, option(
                   "--verify-every", min=0, metavar="K",
                   help="Path trace the ground truth of every K-th frame and report its PSNR (0: none; "
                        "simulated rig).")] = 0,
               quick: Quick = False, no_cache: NoCache = False, truth: TruthArgs = None, rig: RigArgs = None,
               cluster: Cluster = None, workers: Workers = None, max_memory: MaxMemory = None,
               no_floor: NoFloor = False, asked: RenderSettings = None) -> None:
    """Render a sequence over the scene's animation: composite.mp4, bounces.mp4, numbered EXR frames and a
    report with per-frame timings (and, with --verify-every, each verified frame's metrics, cross-transfer
    error and fidelity floor)."""
    from lftransfer.runs.pipeline import RunOptions
    from lftransfer.runs.sequence import MODES, SequenceError, SequenceOptions

    if mode not in MODES:
        fail(f"--mode: expected one of {', '.join(MODES)}, got {mode!r}")
    scene = load(scene_file, quick)
    rig_opts = rig_options(scene, truth, rig)
    spec = cluster_spec(cluster, workers)     # the converged frames and the quiet reference's rounds
    options = RunOptions(settings=asked.overrides(), use_cache=not no_cache, floor=not no_floor,
                         cluster=spec if asked.quiet_reference else None, **rig_opts)
    try:
        seq = SequenceOptions(mode=mode, loop=loop, frames=frames, resume=resume, verify_every=verify_every,
                              cluster=spec if mode == "converged" or not asked.quiet_reference else None)
    except SequenceError as exc:
        fail(str(exc))
    if resume and not (out / "report.json").is_file():
        fail(f"--resume: {out / 'report.json'} does not exist: nothing to resume")
    check_before_work(scene, out_dir=out, cache=verify_every > 0 and not no_cache, bounces=asked.bounces,
                      calibrate=calibrates(scene, rig_opts), max_memory=max_memory)
    report, check = _render_with_progress(scene, out, options, seq)
    _sequence_table(report, out, mode, check)


def register(app: typer.Typer) -> None:
    """Add ``live`` and ``render`` to ``app``."""
    command(app, "live")(live)
    command(app, "render")(render_cmd)
