"""The ``lft`` command."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Light field transfer between real and synthetic objects.")
console = Console(stderr=True)


def _fail(message: str) -> None:
    console.print(f"[bold red]error:[/] {message}", soft_wrap=True, highlight=False)
    raise typer.Exit(code=2)


def _run(scene, out: Path, bounces: int, lighting_model: Optional[str], compare: bool, gt_spp: Optional[int],
         use_cache: bool) -> dict:
    from lftransfer.pipeline import RunOptions, count_run_steps, run_scene

    options = RunOptions(bounces=bounces, lighting_model=lighting_model,
                         compare_models=("area", "point") if compare else (), gt_spp=gt_spp, use_cache=use_cache)
    total = count_run_steps(scene, options)
    with Progress(TextColumn("[bold]{task.description:<58}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), console=console, transient=False) as bar:
        task = bar.add_task("starting", total=total)

        def progress(msg: str, done: int) -> None:
            bar.update(task, description=msg[:58], completed=min(done, total))

        report = run_scene(scene, out, options, progress=progress)
        bar.update(task, description="done", completed=total)
    _summary(report, out)
    return report


def _summary(report: dict, out: Path) -> None:
    table = Table(title=f"light field transfer -> {out}")
    table.add_column("metric")
    table.add_column("value", justify="right")
    for key in ("psnr_db", "psnr_db_direct_only", "cross_transfer_rel_error", "gt_noise_psnr_db",
                "cross_gt_noise_rel"):
        table.add_row(key, f"{report[key]:.4g}")
    for name, m in report["by_lighting_model"].items():
        table.add_row(f"cross error, {name} model", f"{m['cross_transfer_rel_error']:.4g}")
    for b in report["bounces"]:
        table.add_row(f"bounce {b['index']} energy real / synthetic", f"{b['real_energy']:.3g} / {b['synthetic_energy']:.3g}")
    table.add_row("total time", f"{report['timings_s']['total']:.1f} s")
    Console().print(table)


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
         no_cache: bool = typer.Option(False, "--no-cache", help="Render the ground truth again.")) -> None:
    """Run the paper's Fig. 4 scene (10 x 12 hexagonal lenslets) on the simulated rig and check it."""
    from lftransfer.pipeline import quick_scene
    from lftransfer.scenes import builtin_scene

    scene = _load(builtin_scene("fig4"))
    if quick:
        scene = quick_scene(scene)
    _run(scene, out, bounces, None, True, None, not no_cache)


@app.command()
def run(scene_file: Path = typer.Argument(..., help="Scene TOML file."),
        bounces: int = typer.Option(2, min=0, help="Number of bounces."),
        out: Path = typer.Option(Path("out/run"), help="Output folder."),
        lighting_model: Optional[str] = typer.Option(None, help="area | point | prefiltered (default: the scene's)."),
        compare: bool = typer.Option(False, "--compare-models", help="Also measure the other lighting model."),
        gt_spp: Optional[int] = typer.Option(None, help="Ground-truth samples per pixel."),
        quick: bool = typer.Option(False, "--quick", help="Quarter resolution."),
        no_cache: bool = typer.Option(False, "--no-cache", help="Render the ground truth again.")) -> None:
    """Run light field transfer on any scene file with the simulated rig."""
    from lftransfer.pipeline import quick_scene
    from lftransfer.render.lights import LIGHTING_MODELS

    if lighting_model is not None and lighting_model not in LIGHTING_MODELS:
        _fail(f"--lighting-model: expected one of {', '.join(LIGHTING_MODELS)}, got {lighting_model!r}")
    if not scene_file.exists():
        _fail(f"{scene_file}: no such file")
    scene = _load(scene_file)
    if quick:
        scene = quick_scene(scene)
    _run(scene, out, bounces, lighting_model, compare, gt_spp, not no_cache)


def main() -> None:  # pragma: no cover
    logging.basicConfig(level=logging.WARNING)
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
