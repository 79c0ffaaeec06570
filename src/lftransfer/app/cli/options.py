"""Every option of the ``lft`` command, defined once.

An option used by more than one command is an ``Annotated`` type here (its flag, metavar, range and help); the
options that always travel together are *option groups* (:class:`TruthArgs`, :class:`RigArgs`), frozen
dataclasses whose fields become the command's options through :func:`option_groups`. A choice's values and its
default come from :mod:`lftransfer.choices`, so the command line, the scene model and studies agree. Help texts
go through :func:`rich.markup.escape`: TOML tables such as ``[animation]`` are shown, not read as markup.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
from pathlib import Path
from typing import Annotated, Optional, get_type_hints

import typer
from rich.markup import escape

from lftransfer import choices
from lftransfer.scenes import builtin_scenes

__all__ = ["Bounces", "Calibration", "Cluster", "GtSpp", "LightingModel", "MaxMemory", "NoCache", "NoFloor",
           "OutDir", "Projection", "Quick", "QuietReference", "Reconstruction", "Renderer", "RigArgs", "SceneArg",
           "TruthArgs", "Window", "Workers", "choice_check", "flag", "metavar", "option", "option_groups"]


def metavar(choice) -> str:
    """``a|b|c``: a choice's values (:mod:`lftransfer.choices`) as a metavar."""
    return "|".join(choices.values(choice))


def option(*names: str, help: str, **kwargs) -> typer.models.OptionInfo:  # noqa: A002
    """``typer.Option`` with its help escaped for rich (brackets shown as typed)."""
    return typer.Option(*names, help=escape(help), **kwargs)


def flag(name: str, help: str) -> typer.models.OptionInfo:  # noqa: A002
    """A boolean flag shown without a ``<bool>`` type."""
    return option(name, metavar="", help=help)


def choice_check(name: str, choice):
    """A typer callback that refuses a value not among ``choice``'s (one line naming the option)."""

    def check(value):
        if value is not None and value not in choices.values(choice):
            raise typer.BadParameter(f"expected one of {', '.join(choices.values(choice))}, got {value!r}",
                                     param_hint=f"'{name}'")
        return value
    return check


def _memory_check(value: Optional[str]) -> Optional[str]:
    from lftransfer.runs.memory import parse_size

    if value is not None:
        try:
            parse_size(value)
        except ValueError as exc:
            raise typer.BadParameter(str(exc), param_hint="'--max-memory'") from None
    return value


SceneArg = Annotated[Path, typer.Argument(metavar="SCENE.toml", help=escape(
    f"Scene TOML file, or a built-in scene by name ({', '.join(builtin_scenes())})."))]
OutDir = Annotated[Path, option("--out", metavar="DIR", help="Output folder (made if missing).")]
Quick = Annotated[bool, flag("--quick", "Quarter resolution: every device at a quarter of its size, a third of the "
                                        "angular samples (at least 8), a quarter of the ground-truth samples (at "
                                        "least 16).")]
NoCache = Annotated[bool, flag("--no-cache", "Render the ground truth again (do not read or write the cache).")]
QuietReference = Annotated[bool, flag("--quiet-reference", "Render the ground truth in rounds (the objects' pixels "
                                                             "only after the first) until its noise on the cross "
                                                             "term is at most a third of the error; --gt-spp is the "
                                                             "first round's samples.")]
NoFloor = Annotated[bool, flag("--no-floor", "Skip the fidelity floor (on the simulated rig: the best any algorithm "
                                             "could do through this rig, each side; a few hundred renders).")]
MaxMemory = Annotated[Optional[str], option(
    "--max-memory", metavar="SIZE", callback=_memory_check,
    help="Largest memory the run may need, e.g. 64G (default: what the machine has available now). The need is "
         "estimated from the scene before any work.")]
Bounces = Annotated[int, option("--bounces", min=0, max=choices.MAX_BOUNCES, metavar="N",
                                help=f"Number of bounces (0 to {choices.MAX_BOUNCES}).")]
GtSpp = Annotated[Optional[int], option("--gt-spp", min=1, metavar="N",
                                        help="Ground-truth samples per pixel (>= 1; default: the scene's "
                                             f"render.gt_spp, {choices.DEFAULT_GT_SPP} unless the scene says).")]
Renderer = Annotated[str, option("--renderer", metavar=metavar(choices.Renderer),
                                 callback=choice_check("--renderer", choices.Renderer),
                                 help="Synthetic renderer: auto (the fast path where the scene allows it) | fast | "
                                      "exact (path tracing).")]
LightingModel = Annotated[Optional[str], option(
    "--lighting-model", metavar=metavar(choices.LightingModel),
    callback=choice_check("--lighting-model", choices.LightingModel),
    help=f"How the captured light field lights the synthetic objects (default: the scene's render.lighting_model, "
         f"{choices.DEFAULT_LIGHTING_MODEL} unless the scene says).")]
Reconstruction = Annotated[Optional[str], option(
    "--reconstruction", metavar=metavar(choices.Reconstruction),
    callback=choice_check("--reconstruction", choices.Reconstruction),
    help=f"Area model: how the captured light field is read between lenslets (default: the scene's, "
         f"{choices.DEFAULT_RECONSTRUCTION} unless the scene says).")]
Projection = Annotated[Optional[str], option(
    "--projection", metavar=metavar(choices.Projection),
    callback=choice_check("--projection", choices.Projection),
    help=f"Area model: what the projector is sent: the box light field, the light field prefiltered from the "
         f"real scene's depth measured through the rig, or the light field solved against the surface that depth "
         f"measures (default: the scene's, {choices.DEFAULT_PROJECTION} unless the scene says).")]
Window = Annotated[Optional[str], option(
    "--window", metavar=metavar(choices.Window), callback=choice_check("--window", choices.Window),
    help=f"Area model: what the synthetic objects receive from beyond the lenslets' window: the captured light "
         f"field read at the window's edge, or nothing (default: the scene's, {choices.DEFAULT_WINDOW} unless the "
         f"scene says).")]
Composite = Annotated[Optional[str], option(
    "--composite", metavar=metavar(choices.Composite), callback=choice_check("--composite", choices.Composite),
    help=f"How the final frame is put together: the synthetic render over the real view, or the nearer surface per "
         f"pixel (the real scene's depth measured through the rig, carried into the view camera; default: the "
         f"scene's, {choices.DEFAULT_COMPOSITE} unless the scene says).")]
DirectLight = Annotated[Optional[str], option(
    "--direct-light", metavar=metavar(choices.DirectLight),
    callback=choice_check("--direct-light", choices.DirectLight),
    help="What lights the synthetic objects directly: the scene's point lights, or the environment its light probe "
         "shows; on a light probe scene, point is one point light at the probe's brightest direction, for "
         "comparison (default: probe where the scene's [light] has kind = 'probe', else point).")]
Cluster = Annotated[Optional[str], option(
    "--cluster", metavar="auto|local|ray://HOST:PORT",
    help="Spread the work over a Ray cluster (pip install 'lftransfer[cluster]'): auto (the cluster `ray start` "
         "made here, else a local one) | local (one started for this job) | ray://HOST:PORT. Results are "
         "bit-identical to one process (a quiet reference, split into one part per worker, to one process that "
         "splits it alike).")]
Workers = Annotated[Optional[int], option("--workers", min=1, metavar="N",
                                          help="Cluster workers (default: one per GPU, else per CPU core).")]
Calibration = Annotated[Optional[Path], option(
    "--calibration", metavar="FILE",
    help="Use this calibration file (from `lft calibrate`, or a run's calibration.json) instead of calibrating.")]


@dataclasses.dataclass(frozen=True)
class TruthArgs:
    """The simulated rig's hidden truth: how the rig as built differs from the rig file."""

    truth_seed: Annotated[int, option("--truth-seed", min=0, metavar="N", help=(
        "Seed (>= 0) of the simulated rig's hidden truth (how the rig as built differs from the rig file)."))] = 0
    exact_rig: Annotated[bool, flag("--exact-rig", "Build the simulated rig exactly as the rig file says (no hidden "
                                                   "deviations).")] = False

    @property
    def seed(self) -> int | None:
        """The truth seed a run takes (None: exactly as the files say)."""
        return None if self.exact_rig else self.truth_seed


@dataclasses.dataclass(frozen=True)
class RigArgs:
    """Which rig a command uses and what it knows of it."""

    rig: Annotated[str, option("--rig", metavar="SPEC", help=(
        "Which rig: sim (simulated, default) | hardware:RIG.toml (a physical rig, or the device twin) | "
        "replay:DIR (a recording)."))] = "sim"
    rig_model: Annotated[str, option(
        "--rig-model", metavar=metavar(choices.RigModel), callback=choice_check("--rig-model", choices.RigModel),
        help="What the pipeline knows of the rig: calibrated (calibrate through the rig first) | nominal (the rig "
             "file's values) | oracle (the simulated rig's hidden truth: what perfect calibration would reach).")
    ] = choices.DEFAULT_RIG_MODEL
    calibration: Calibration = None


def option_groups(command):
    """Give ``command`` the options of each parameter annotated with an option group (a dataclass above): typer
    sees the group's fields as options; the command receives one group object per such parameter."""
    signature = inspect.signature(command)
    hints = get_type_hints(command, include_extras=True)
    groups = {name: hint for name, hint in hints.items() if dataclasses.is_dataclass(hint)}
    params = [p.replace(annotation=hints.get(p.name, p.annotation)) for p in signature.parameters.values()
              if p.name not in groups]
    fields = {}
    for name, group in groups.items():
        group_hints = get_type_hints(group, include_extras=True)
        for f in dataclasses.fields(group):
            fields.setdefault(name, []).append(f.name)
            params.append(inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, default=f.default,
                                            annotation=group_hints[f.name]))

    @functools.wraps(command)
    def wrapper(**kwargs):
        for name, group in groups.items():
            kwargs[name] = group(**{f: kwargs.pop(f) for f in fields[name]})
        return command(**kwargs)

    wrapper.__signature__ = signature.replace(parameters=params, return_annotation=inspect.Signature.empty)
    wrapper.__annotations__ = {p.name: p.annotation for p in params}
    del wrapper.__wrapped__
    return wrapper
