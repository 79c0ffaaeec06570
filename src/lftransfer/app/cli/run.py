"""``lft demo``, ``lft run`` and ``lft record``: one complete run (:func:`lftransfer.runs.pipeline.run_scene`)
with a progress bar and a summary table."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from lftransfer import choices
from lftransfer.app.cli.common import (calibrates, check_before_work, cluster_spec, command, ending_cleanly, load,
                                       operator, progress_bar, rig_options, row)
from lftransfer.app.cli.options import (Calibration, Cluster, MaxMemory, NoCache, NoFloor, OutDir, Quick, RigArgs,
                                        SceneArg, TruthArgs, Workers, flag, option, setting_options)
from lftransfer.app.terminal import fail, warn

__all__ = ["register"]

DemoSettings = setting_options("bounces", "renderer", "quiet_reference", "reference_budget_s")
RunSettings = setting_options("bounces", "lighting_model", "reconstruction", "projection", "window", "composite",
                              "direct_light", "gt_spp", "renderer", "quiet_reference", "reference_budget_s",
                              defaults=(("quiet_reference", True),))
"""``lft run`` judges the run it makes: its reference is made quiet enough by default, within a time budget
(``lft demo`` keeps the fixed reference its stored results were measured against; ``--quiet-reference`` there)."""
RecordSettings = setting_options("bounces", "renderer")

METRICS = ("psnr_db", "psnr_db_direct_only", "psnr_objects_db", "psnr_objects_db_direct_only",
           "cross_transfer_rel_error", "gt_noise_psnr_db", "cross_gt_noise_rel")


def _run(scene, out: Path, options) -> dict:
    """Run the pipeline with a progress bar; a fault, a calibration file that does not fit or Ctrl-C ends in one
    line that says where the run folder stands."""
    from lftransfer.runs.pipeline import count_run_steps, run_scene
    from lftransfer.runs.rigs import CalibrationFailedError
    from lftransfer.calibration.rig import CalibrationFileError
    from lftransfer.rig.base import RigError

    total = count_run_steps(scene, options)
    status = out / "status.json"
    with progress_bar(58) as bar:
        task = bar.add_task("starting", total=total)

        def progress(msg: str, done: int) -> None:
            bar.update(task, description=escape(msg[:58]), completed=min(done, total))

        with ending_cleanly(bar, interrupted=f"interrupted; what was written so far is in {out}, and {status} says "
                                             f"'interrupted'", refused=(CalibrationFileError,),
                            failed=(RigError, CalibrationFailedError),
                            where=f"what was written so far is in {out}; {status} says where it stopped"):
            report = run_scene(scene, out, options, progress=progress, operator=operator(bar), warn=warn)
        bar.update(task, description="done", completed=total)
    summary(report, out)
    return report


def control_line(control: dict) -> str:
    """The negative control in one line: its psnr_objects_db and cross error, and the run's margins over it."""
    def num(key: str, spec: str) -> str:
        return "undefined" if control.get(key) is None else format(control[key], spec)

    verdict = "measurably worse" if control["measurably_worse"] else "NOT measurably worse"
    return (f"psnr_objects_db {num('psnr_objects_db', '.4g')} dB, cross error "
            f"{num('cross_transfer_rel_error', '.3g')}; the run better by {num('psnr_objects_margin_db', '+.3g')} "
            f"dB and {num('cross_error_margin', '+.3g')}: {verdict}")


def floor_line(floor: dict) -> str:
    """The fidelity floor in one line: each side's floor against the transfer (scored alike), the whole and the
    ratio."""
    def side(name: str) -> str:
        s = floor.get(name)
        return "none" if s is None else f"{s['floor']:.3g} (transfer {s['transfer']:.3g})"

    whole = "undefined" if floor.get("floor") is None else f"{floor['floor']:.3g}"
    ratio = "undefined" if floor.get("transfer_over_floor") is None else f"{floor['transfer_over_floor']:.3g}"
    return f"{side('real')} / {side('synthetic')}; floor {whole}, transfer / floor {ratio}"


def summary(report: dict, out: Path) -> None:
    """A run's verdict in one line, then its report as a table on stdout, and why each undefined metric is
    undefined."""
    if report.get("verdict"):
        Console().print(escape(f"verdict: {report['verdict']['reading']}"), soft_wrap=True, highlight=False)
    table = Table(title=escape(f"light field transfer -> {out}"))
    table.add_column("metric")
    table.add_column("value", justify="right")
    row(table, "rig", report["rig"])
    row(table, "verification", report["verification"])
    settings = report.get("settings", {}).get("transfer", {})
    if settings:
        row(table, "settings.transfer", f"{settings['lighting_model']} model, {settings['reconstruction']} reconstruction, "
                               f"{settings['projection']} projection, {settings['window']} window, "
                               f"{settings['bounces']} bounces, {report['renderer']} renderer")
    undefined = report.get("undefined_metrics") or {}
    for key in METRICS:
        if report.get(key) is not None:
            row(table, key, f"{report[key]:.4g}")
        elif key in undefined:
            row(table, key, "undefined (see below)")
    for key in ("by_lighting_model", "by_reconstruction", "by_projection", "by_window"):
        by_choice = report.get(key) or {}
        for name, m in by_choice.items():
            if len(by_choice) > 1 and m.get("cross_transfer_rel_error") is not None:
                row(table, f"{key}.{name}.cross_transfer_rel_error", f"{m['cross_transfer_rel_error']:.4g}")
    ref = report.get("reference")
    if ref is not None:
        row(table, "reference", f"{ref['spp']} samples per pixel in {ref['rounds']} rounds; noise "
                                      f"{ref['noise']:.3g} = {ref['ratio']:.2g} of the error (target "
                                      f"{ref['target']:.2g}{', met' if ref['met'] else ', NOT met'})"
            if ref.get("ratio") is not None else "no error to judge")
    floor = report.get("fidelity_floor")
    if floor is not None:
        row(table, "fidelity_floor (real / synthetic)", floor_line(floor))
    control = report.get("negative_control")
    if control is not None:
        row(table, f"negative_control ({control['rig_model']})", control_line(control))
    for b in report["bounces"]:
        row(table, f"bounces[{b['index']}] real_energy / synthetic_energy",
            f"{b['real_energy']:.3g} / {b['synthetic_energy']:.3g}")
    row(table, "rig_model", report["rig_model"])
    errors = report.get("calibration_errors") or {}
    each = errors.get("interfaces") or {"": errors}          # several interfaces: each one's errors
    for name, e in each.items():
        if not name:
            if "lenslet_centre_rms_px" in e:
                row(table, "calibration_errors.lenslet_centre_rms_px", f"{e['lenslet_centre_rms_px']:.3f} px")
            key = "calibration_errors.pose_position_rms_mm / pose_rotation_deg"
        else:
            key = f"calibration_errors: {name}'s pose"
        if "pose_position_rms_mm" in e and "pose_rotation_deg" in e:
            row(table, key, f"{e['pose_position_rms_mm']:.2f} mm / {e['pose_rotation_deg']:.3f} deg")
    row(table, "timings_s.total", f"{report['timings_s']['total']:.1f} s")
    Console().print(table)
    for key, reason in undefined.items():
        Console().print(escape(f"{key} is undefined: {reason}"), soft_wrap=True, highlight=False)


def demo(out: OutDir = Path("out/demo"), quick: Quick = False, no_cache: NoCache = False, truth: TruthArgs = None,
         rig: RigArgs = None, max_memory: MaxMemory = None, no_floor: NoFloor = False,
         asked: DemoSettings = None) -> None:
    """Run the paper's Fig. 4 scene (10 x 12 hexagonal lenslets), by default on the simulated rig: calibrate,
    transfer, check against ground truth (both lighting models, both reconstructions, every projection, both
    windows) and against a negative control (the rig file's nominal values, uncalibrated)."""
    from lftransfer.runs.pipeline import RunOptions

    scene = load(None, quick)
    rig_opts = rig_options(scene, truth, rig)
    options = RunOptions(settings=asked.overrides(compare_all=True), use_cache=not no_cache, negative_control=True,
                         floor=not no_floor, **rig_opts)
    check_before_work(scene, out_dir=out, cache=not no_cache and rig_opts["rig"].kind != "hardware",
                      bounces=asked.bounces, calibrate=calibrates(scene, rig_opts), max_memory=max_memory)
    _run(scene, out, options)


def run(scene_file: SceneArg, out: OutDir = Path("out/run"),
        compare: Annotated[bool, flag("--compare-models", "Also measure the other lighting model (area or "
                                                          "point), the other reconstruction, the other "
                                                          "projections and the other window, each a full "
                                                          "re-run.")] = False,
        quick: Quick = False, no_cache: NoCache = False, truth: TruthArgs = None, rig: RigArgs = None,
        max_memory: MaxMemory = None, no_floor: NoFloor = False, cluster: Cluster = None, workers: Workers = None,
        time_s: Annotated[Optional[float], option("--time", min=0.0, metavar="SECONDS", help=(
            "The moment of an animated scene the run renders (default 0; the run says which; lft render renders "
            "the whole animation)."))] = None,
        asked: RunSettings = None) -> None:
    """Run light field transfer on any scene file with a rig (calibrating it first); --cluster spreads a quiet
    reference's rounds over a Ray cluster."""
    from lftransfer.runs.pipeline import RunOptions

    spec = cluster_spec(cluster, workers)
    if spec is not None and not asked.quiet_reference:
        fail("--cluster: lft run spreads a quiet reference's rounds over it; add --quiet-reference")

    scene = load(scene_file, quick)
    rig_opts = rig_options(scene, truth, rig)
    if time_s is not None and not scene.moving:
        fail(f"--time {time_s:g}: the scene is still (no object has keyframes), so every moment is the same")
    options = RunOptions(settings=asked.overrides(compare_all=compare), use_cache=not no_cache, floor=not no_floor,
                         cluster=spec, time_s=time_s, **rig_opts)
    check_before_work(scene, out_dir=out, cache=not no_cache and rig_opts["rig"].kind != "hardware",
                      bounces=asked.bounces, calibrate=calibrates(scene, rig_opts), max_memory=max_memory)
    _run(scene, out, options)


def record(scene_file: SceneArg,
           out: Annotated[Path, option("--out", metavar="DIR", help="Session folder: the recording, and the "
                                                                   "run's outputs in run/.")],
           rig_spec: Annotated[str, option("--rig", metavar="SPEC", help="Which rig to record: sim | "
                                                                       "hardware:RIG.toml.")] = "sim",
           quick: Quick = False, truth: TruthArgs = None, calibration: Calibration = None,
           max_memory: MaxMemory = None, asked: RecordSettings = None) -> None:
    """Calibrate and run transfer on a rig (sim or hardware:RIG.toml) while storing every request and image
    it answers (replay it with lft run SCENE.toml --rig replay:SESSION)."""
    from lftransfer.runs.pipeline import RunOptions

    rig = RigArgs(rig=rig_spec, rig_model=choices.DEFAULT_RIG_MODEL, calibration=calibration)
    if rig.rig.startswith("replay"):
        fail("--rig: a recording is recorded already; record from sim or hardware:RIG.toml")
    if (out / "manifest.json").exists():
        fail(f"--out {out}: holds a recording already; choose an empty folder")
    scene = load(scene_file, quick)
    rig_opts = rig_options(scene, truth, rig)
    options = RunOptions(settings=asked.overrides(), record=out, **rig_opts)
    check_before_work(scene, out_dir=out, cache=rig_opts["rig"].kind == "sim", bounces=asked.bounces,
                      calibrate=calibrates(scene, {**rig_opts, "record": out}), max_memory=max_memory)
    _run(scene, out / "run", options)
    Console().print(escape(f"recorded the session into {out} (replay: lft run {scene_file} --rig replay:{out}"
                           f"{' --quick' if quick else ''} --bounces {asked.bounces})"), soft_wrap=True)


def register(app: typer.Typer) -> None:
    """Add ``demo``, ``run`` and ``record`` to ``app``."""
    command(app)(demo)
    command(app)(run)
    command(app)(record)
