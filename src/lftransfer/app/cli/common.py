"""What every ``lft`` command shares: its command class, scene loading, the checks made before any work (one
line, exit code 2), the rig options turned into run options, the operator prompt, progress bars and tables."""

from __future__ import annotations

import functools
import inspect
import re
from contextlib import contextmanager
from pathlib import Path
from typing import Optional

import typer
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Column, Table
from typer.core import TyperCommand

from lftransfer.app.cli.options import RigArgs, TruthArgs, option_groups
from lftransfer.app.terminal import FAILED, INTERRUPTED, LftGroup, console, fail, say

__all__ = ["Command", "Group", "check_before_work", "cluster_spec", "command", "ending_cleanly", "load", "operator",
           "progress_bar", "rig_options", "rig_spec", "row", "step_bar", "sub_app"]


class _PlainHelp:
    """Help that shows flags without a ``<bool>`` type (mixed into the command and the group)."""

    def get_help_option(self, ctx):  # noqa: ANN001, ANN201
        option = super().get_help_option(ctx)
        if option is not None:
            option.metavar = ""
        return option


class Command(_PlainHelp, TyperCommand):
    """A command whose help shows flags without a ``<bool>`` type."""


class Group(_PlainHelp, LftGroup):
    """A group of ``lft`` commands, with the same help and one-line errors."""


def sub_app(help: str, cls: type = Group, **kwargs) -> typer.Typer:  # noqa: A002
    """A typer app for a command group (``lft calibrate``, ``lft twin``), its help escaped for rich."""
    return typer.Typer(cls=cls, no_args_is_help=True, help=escape(help), **kwargs)


def command(app: typer.Typer, name: str | None = None):
    """Register a function as a command of ``app``: its option groups expanded (:func:`option_groups`), its
    docstring as help with brackets shown as typed, and a first line on stderr as soon as it starts (on a terminal
    or not: a command is never silent while it loads its scene and its renderer)."""
    def decorate(fn):
        doc = "\n\n".join(" ".join(p.split()) for p in (inspect.getdoc(fn) or "").split("\n\n"))
        first = re.split(r"(?<!Fig)(?<!e\.g)(?<!i\.e)\.\s", doc.split("\n\n")[0] + " ", maxsplit=1)[0].rstrip(". ")
        label = " ".join(part for part in ("lft", app.info.name, name or fn.__name__.replace("_", "-")) if part)

        @functools.wraps(fn)
        def announced(*args, **kwargs):
            say(f"{label}: starting")
            return fn(*args, **kwargs)

        return app.command(name, cls=Command, help=escape(doc), short_help=escape(first + "."))(
            option_groups(announced))
    return decorate


def row(table: Table, *cells: object) -> None:
    """One table row, its cells shown as typed."""
    table.add_row(*(escape(str(c)) for c in cells))


def parse_memory(text: Optional[str]) -> Optional[int]:
    """``--max-memory`` in bytes (None: not given)."""
    from lftransfer.runs.memory import parse_size

    return None if text is None else parse_size(text)


def cluster_spec(cluster: Optional[str], workers: Optional[int]):
    """``--cluster`` and ``--workers`` -> ClusterSpec, or None for one process (a usage error names the option)."""
    from lftransfer.runs.cluster import ClusterSpec

    if cluster is None:
        if workers is not None:
            fail("--workers: needs --cluster")
        return None
    try:
        return ClusterSpec.parse(cluster, workers)
    except ValueError as exc:
        fail(str(exc))


def rig_spec(rig: str):
    """``--rig`` -> RigSpec (a usage error names what is wrong)."""
    from lftransfer.runs.rigs import RigSpec

    try:
        return RigSpec.parse(rig)
    except ValueError as exc:
        fail(str(exc))


def rig_options(scene, truth: TruthArgs, rig: RigArgs) -> dict:
    """The rig part of the run options (``truth_seed``, ``rig_model``, ``calibration``, ``rig``), checked; a
    calibration file is read and checked against the scene."""
    from lftransfer.calibration.interfaces import read_calibration

    spec = rig_spec(rig.rig)
    if rig.rig_model == "oracle" and spec.kind != "sim":
        fail("--rig-model oracle: only the simulated rig (--rig sim) knows its truth")
    if rig.calibration is not None:
        if not rig.calibration.is_file():
            fail(f"--calibration {rig.calibration}: no such file")
        read_calibration(rig.calibration, scene)              # CalibrationFileError: one line, exit code 2
    return {"truth_seed": truth.seed, "rig_model": rig.rig_model, "calibration": rig.calibration, "rig": spec,
            "recalibrate": rig.recalibrate}


def calibrates(scene, rig_opts: dict) -> bool:
    """Whether a command with these rig options (:func:`rig_options`) calibrates through the rig first; where it
    reuses the calibration cache's entry for this simulated rig instead, one line says so."""
    from lftransfer.runs.pipeline import RunOptions
    from lftransfer.runs.rigs import cached_calibration

    options = RunOptions(**rig_opts)
    if options.calibration is not None or options.rig_model != "calibrated":
        return False
    entry = cached_calibration(scene, options)
    if entry is None:
        return True
    say(f"reusing this simulated rig's calibration from the cache ({entry.folder}); --recalibrate makes a new one")
    return False


def operator(bar: Progress | None = None):
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


def load(path: Optional[Path], quick: bool):
    """The scene (the built-in Fig. 4 scene for None; a built-in scene's name, e.g. ``fig6``, for a path that does
    not exist and has no suffix), at quarter size with ``quick``; sizes checked."""
    from lftransfer.scenes import check_resolution, quick_scene
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


def check_before_work(scene, *, out_dir: Optional[Path] = None, out_file: Optional[Path] = None,
                      out_option: str = "--out", example: Optional[str] = None, cache: bool = False,
                      bounces: Optional[int] = None, calibrate: bool = True, max_memory: Optional[str] = None) -> None:
    """Output paths, the ground-truth cache and the memory estimate, before any work (one line, exit code 2)."""
    from lftransfer.runs.memory import check_memory, estimate_memory
    from lftransfer.runs.paths import check_cache_dir, check_output_dir, check_output_file

    if out_dir is not None:
        check_output_dir(out_dir, out_option)
    if out_file is not None:
        check_output_file(out_file, out_option, example)
    if cache:
        from lftransfer.sim.gt_cache import cache_dir

        check_cache_dir(cache_dir())
    check_memory(estimate_memory(scene, calibrate=calibrate, **({} if bounces is None else {"bounces": bounces})),
                 parse_memory(max_memory))


@contextmanager
def ending_cleanly(bar: Progress, *, interrupted: str, refused: tuple = (), failed: tuple = (), where: str = ""):
    """Work under a progress bar that ends in one line, the bar stopped first: Ctrl-C says ``interrupted`` (exit
    code ``INTERRUPTED``); an error of a class in ``refused`` (bad input found late) its message (exit 1); one in
    ``failed`` (a device, a calibration, a cluster) its message and ``where`` what was written stands (exit
    ``FAILED``)."""
    try:
        yield
    except KeyboardInterrupt:
        bar.stop()
        fail(interrupted, INTERRUPTED)
    except refused as exc:
        bar.stop()
        fail(str(exc))
    except failed as exc:
        bar.stop()
        fail(f"{exc} ({where})", FAILED)


class _Bar(Progress):
    """rich's progress bar; off a terminal (a log, a pipe), where it would draw nothing until it stopped, each new
    description is printed as a line with the steps done."""

    def update(self, task_id, *, description: str | None = None, **kwargs) -> None:
        task = self._tasks.get(task_id)
        if description is not None and task is not None and description != task.description \
                and not self.console.is_terminal:
            done, total = kwargs.get("completed", task.completed), kwargs.get("total", task.total)
            self.console.print(f"{int(done)}/{int(total)} {description}" if total else description, soft_wrap=True,
                               highlight=False)
        super().update(task_id, description=description, **kwargs)


def progress_bar(width: int, *extra: TextColumn) -> Progress:
    """The ``lft`` progress bar: the description (at most ``width`` characters, fewer on a narrow terminal, cut
    with an ellipsis: the counts and the time always show), the bar, done / total, ``extra`` columns, the time
    elapsed. Off a terminal each step is a line (:class:`_Bar`)."""
    description = TextColumn("[bold]{task.description}", table_column=Column(
        ratio=1, no_wrap=True, overflow="ellipsis", min_width=12, max_width=width))
    return _Bar(description, BarColumn(bar_width=20), TextColumn("{task.completed}/{task.total}"), *extra,
                TimeElapsedColumn(), console=console)


@contextmanager
def step_bar(total: int):
    """A progress bar that advances by one on every message; yields the callback."""
    with progress_bar(58) as bar:
        task = bar.add_task("starting", total=total)
        done = [0]

        def progress(msg: str) -> None:
            done[0] += 1
            bar.update(task, description=escape(msg[:58]), completed=min(done[0], total))

        yield progress
        bar.update(task, description="done", completed=total)
