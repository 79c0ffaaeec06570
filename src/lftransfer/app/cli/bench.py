"""``lft bench``: the live loop's step timed on the simulated rig, against the floor of casting its rays once."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from lftransfer import choices
from lftransfer.app.cli.common import calibrates, check_before_work, command, load, rig_options, row, step_bar
from lftransfer.app.cli.options import (Calibration, MaxMemory, Quick, Recalibrate, RigArgs, TruthArgs, choice_check,
                                        flag, metavar, option, setting_options)
from lftransfer.app.terminal import FAILED, fail
from lftransfer.reports.results_format import surface_solve_text

__all__ = ["register"]

BenchSettings = setting_options("lighting_model", "reconstruction", "projection", "renderer", "simulator",
                                "simulator_threads", "simulator_nice", "simulator_share", "renderer_threads")


def bench(scene_file: Annotated[Optional[Path], option("--scene", metavar="SCENE.toml",
                                                       help="Scene TOML (default: Fig. 4).")] = None,
          json_out: Annotated[Optional[Path], option("--json", metavar="FILE",
                                                     help="Write the results and the settings used as JSON "
                                                          "here.")] = None,
          iterations: Annotated[int, option("--iterations", min=1, metavar="N",
                                            help="Timed frames of the live step (>= 1), after two warm-up "
                                                 "frames (the first compiles the kernels, the second builds "
                                                 "the culling tiles).")] = 10,
          calibration: Calibration = None, recalibrate: Recalibrate = False,
          rig_model: Annotated[str, option(
              "--rig-model", metavar=metavar(choices.RigModel),
              callback=choice_check("--rig-model", choices.RigModel),
              help="The rig model the step uses: calibrated (what a run uses, default: the bench calibrates "
                   "the simulated rig first) | nominal | oracle (neither is what users run; the output says "
                   "so).")] = choices.DEFAULT_RIG_MODEL,
          truth: TruthArgs = None,
          accuracy: Annotated[bool, option("--accuracy/--no-accuracy", metavar="", help=(
              "Also render the last frame with the exact path and report the fast path's PSNR against it."))
          ] = True,
          peer: Annotated[bool, option("--peer/--no-peer", metavar="", help=(
              "Also time Mitsuba's path integrator on the light field job (point model), at equal RMSE."))
          ] = True,
          quick: Quick = False,
          live: Annotated[bool, flag("--live", (
              "Time the step with a synthetic object moving (a still scene's first synthetic object slides 2 cm "
              "and turns 20 degrees and back over the frames; an animated scene moves as its keyframes "
              "say), and then run the decoupled loop as lft live does: frames per second with the capture "
              "beside them, capture rate and age, motion-to-composite latency."))] = False,
          sync: Annotated[bool, flag("--sync", "With --live: time the synchronous loop only (no decoupled "
                                               "run).")] = False,
          max_memory: MaxMemory = None, asked: BenchSettings = None) -> None:
    """Time the live loop's step (LiveTransfer.step) on the simulated rig with the calibrated rig model and
    the scene's samples: the pipeline's stages apart from the rig's capture, against the floor of casting the
    step's rays once."""
    from lftransfer.runs.bench.step import BenchOptions, count_bench_steps, run_bench, with_moving_object
    from lftransfer.reports.report import write_json
    from lftransfer.runs.rigs import CalibrationFailedError
    from lftransfer.app.terminal import say
    from lftransfer.rig.base import RigError

    scene = load(scene_file, quick)
    if live:
        try:
            scene = with_moving_object(scene, iterations + 1)
        except ValueError as exc:
            fail(str(exc))
    rig_opts = rig_options(scene, truth, RigArgs(rig="sim", rig_model=rig_model, calibration=calibration,
                                                 recalibrate=recalibrate))
    calibrating = calibrates(scene, rig_opts)
    check_before_work(scene, out_file=json_out, out_option="--json", example="bench.json", calibrate=calibrating,
                      max_memory=max_memory)
    options = BenchOptions(iterations=iterations, settings=asked.overrides(), truth_seed=rig_opts["truth_seed"],
                           rig_model=rig_model, calibration=calibration, recalibrate=recalibrate, accuracy=accuracy,
                           peer=peer, decoupled=live and not sync)
    if calibrating:
        say("The bench calibrates the simulated rig first (the model a run uses): this takes minutes at full "
            "resolution (about 10 on 2 cores; about 1.5 with --quick). --calibration FILE skips it."
            + _demo_calibration_hint(scene))
    try:
        with step_bar(count_bench_steps(scene, options)) as progress:
            result = run_bench(scene, options, progress=progress)
    except CalibrationFailedError as exc:
        fail(str(exc), FAILED)
    except RigError as exc:
        fail(f"bench failed: {exc}", FAILED)
    data = result.to_json()
    data["settings"]["quick"] = quick
    data["settings"]["live"] = live
    data["settings"]["command"] = _bench_command(scene_file, quick, iterations, calibration, rig_model, truth, asked,
                                                 accuracy, peer, live, sync)
    _bench_table(result)
    if json_out is not None:
        write_json(json_out, data)
        say(f"wrote {json_out}")


def register(app: typer.Typer) -> None:
    """Add ``bench`` to ``app``."""
    command(app)(bench)


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


def _bench_command(scene_file, quick, iterations, calibration, rig_model, truth, asked, accuracy, peer, live=False,
                   sync=False) -> str:
    """The ``lft bench`` command line that reproduces a run (without --json and --max-memory)."""
    import shlex

    parts = ["lft", "bench"]
    if scene_file is not None:
        parts += ["--scene", str(scene_file)]
    if quick:
        parts.append("--quick")
    if live:
        parts.append("--live")
    if live and sync:
        parts.append("--sync")
    parts += ["--iterations", str(iterations)]
    if calibration is not None:
        parts += ["--calibration", str(calibration)]
    elif rig_model != choices.DEFAULT_RIG_MODEL:
        parts += ["--rig-model", rig_model]
    if truth.exact_rig:
        parts.append("--exact-rig")
    elif truth.truth_seed != 0:
        parts += ["--truth-seed", str(truth.truth_seed)]
    parts += asked.arguments()
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
    row(table, "rig model", s["rig_model"])
    row(table, "settings", f"{s['lighting_model']} model, {s['reconstruction']} reconstruction, "
                            f"{s['renderer']['used']} renderer, {s['angular_samples']}^2 angular samples, "
                            f"lf {s['lf_spp']} / view {s['view_spp']} spp, {s['aperture_samples']} aperture points")
    row(table, "resolution", f"LF camera {res['lf_camera'][0]}x{res['lf_camera'][1]}, projector "
                              f"{res['projector'][0]}x{res['projector'][1]}, view {res['view'][0]}x{res['view'][1]}, "
                              f"{res['lenslets'][0]}x{res['lenslets'][1]} lenslets")
    p = result.pipeline_iteration
    row(table, "pipeline_iteration_ms (median)",
         f"{result.pipeline_iteration_ms:.1f} ms (min {p.min:.1f}, max {p.max:.1f}; {s['iterations']} frames)")
    labels = {"incident_light": "captured light field as a light", "render_lightfield": "relight + render light field"}
    for stage, t in result.stages_ms.items():
        row(table, f"  {labels.get(stage, stage.replace('_', ' '))}", f"{t.median:.1f} ms")
        if stage == "encode" and result.surface_solve is not None:
            row(table, "    of which the surface solve", surface_solve_text(result.surface_solve))
    rig = result.rig_stages_ms
    row(table, "rig capture (simulator; not in the pipeline)",
         f"{result.capture_ms:.0f} ms (LF {rig['capture'].median:.0f}, view {rig['capture_view'].median:.0f})")
    row(table, "rig setup/project, bookkeeping (in neither)", f"{result.unstaged_ms:.1f} ms")
    f = result.floor
    where = {"scene": "the scene's shapes", "renderer": "the renderer's geometry"}[f.geometry]
    row(table, "floor_ms (the step's rays cast once)", f"{result.floor_ms:.1f} ms ({sum(f.rays):,} rays, "
                                                        f"{where})")
    other = f.renderer_geometry_ms if f.geometry == "scene" else f.scene_geometry_ms
    if other is not None:
        row(table, "  same rays, the other geometry", f"{other:.1f} ms")
    row(table, "iteration_over_floor", f"{result.iteration_over_floor:.1f}x")
    row(table, "frames per second: pipeline / whole step", f"{result.pipeline_fps:.2f} / {result.step_fps:.3f} "
                                                            f"(the step includes the simulator's capture)")
    row(table, "frames in which a synthetic object moved", f"{result.frames_moved} of {s['iterations']}")

    def latency(x) -> str:
        return "-" if x is None else f"{x['median']:.0f} ms (95 %: {x['p95']:.0f} ms)"

    for loop, lat in (result.latency_ms or {}).items():
        if lat is not None:
            row(table, f"motion to composite / to its light ({loop})",
                 f"{latency(lat['view'])} / {latency(lat['light'])}")
    d = result.decoupled
    if d is not None:
        row(table, "decoupled: frames per second (captures beside them)",
             f"{d.render_fps:.2f} ({d.frames} frames in {d.seconds:.1f} s, {d.frame_ms:.0f} ms per frame)")
        row(table, "decoupled: frames per second, captures held (the renderer alone)",
             f"{d.render_fps_alone:.2f}: with the simulator beside it {100 * d.rate_with_simulator:.0f} % of that; "
             f"cores busy {d.cores_busy:.2f} against {d.cores_busy_alone:.2f}")
        sim = d.simulator
        row(table, "decoupled: the simulator",
             f"in its own process ({sim['threads']} thread(s), nice {sim['nice']}), {d.simulator_cores_busy:.2f} cores "
             f"busy" if sim["where"] == "process" and d.simulator_cores_busy is not None else
             "in the loop's process (its cores busy counted with the loop's)")
        row(table, "decoupled: capture rate, capture age",
             f"{d.capture_hz:.3g} /s ({d.captures} captures), median {d.capture_age_s['median']:.2f} s, "
             f"at most {d.capture_age_s['max']:.2f} s")
    if result.fast_vs_exact is not None:
        v, o = result.fast_vs_exact.psnr_db, result.fast_vs_exact.psnr_objects_db
        row(table, "fast vs exact composite PSNR: all / objects", "n/a (exact path)" if v is None else
             f"{v:.1f} dB / " + ("n/a" if o is None else f"{o:.1f} dB"))
    if result.peer is not None:
        q = result.peer
        bound = "" if q.reached_target else " (lower bound: the peer missed our RMSE)"
        row(table, "peer: light field job, point model", f"ours {q.ours_ms:.0f} ms, Mitsuba path {q.peer_ms:.0f} ms "
                                                          f"at {q.peer_spp} spp")
        row(table, "peer ratio", f"{q.ratio:.0f}x{bound}")
    row(table, "variant, peak RSS", f"{s['variant']}, {result.peak_rss_mb:.0f} MB")
    Console().print(table)
    for note in result.notes:
        Console().print(escape(f"note: {note}"), soft_wrap=True, highlight=False)
