"""Every option of the ``lft`` command, defined once.

A run's settings are not defined here: each is a field of :class:`lftransfer.settings.Overrides`, whose metadata
holds its help, its choice and its bounds, and :func:`setting_options` makes a command's options from the fields it
names (an option group that gives the command its ``Overrides``). A choice's values and its default come from
:mod:`lftransfer.choices`, so the command line, the page, the scene model and studies agree.

Any other option used by more than one command is an ``Annotated`` type here (its flag, metavar, range and help);
the options that always travel together are *option groups* (:class:`TruthArgs`, :class:`RigArgs`, the settings'
groups), frozen dataclasses whose fields become the command's options through :func:`option_groups`. Help texts go
through :func:`rich.markup.escape`: TOML tables such as ``[animation]`` are shown, not read as markup.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
from pathlib import Path
from typing import Annotated, Optional, get_args, get_type_hints

import typer
from rich.markup import escape

from lftransfer import choices
from lftransfer.scenes import builtin_scenes
from lftransfer.settings import Overrides

__all__ = ["Calibration", "Cluster", "MaxMemory", "NoCache", "NoFloor", "OutDir", "Quick", "Recalibrate", "RigArgs",
           "SceneArg", "SettingOptions", "TruthArgs", "Workers", "choice_check", "flag", "metavar", "option",
           "option_groups", "setting_options"]


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
OutDir = Annotated[Path, option("--out", metavar="DIR", help=(
    "Output folder (made if missing): the images, report.json and status.json the command writes (README, 'Your "
    "first hour', lists them)."))]
Quick = Annotated[bool, flag("--quick", "Quarter resolution: every device at a quarter of its size, a third of the "
                                        "angular samples (at least 8), a quarter of the ground-truth samples (at "
                                        "least 16).")]
NoCache = Annotated[bool, flag("--no-cache", "Render the ground truth again (do not read or write the cache).")]
NoFloor = Annotated[bool, flag("--no-floor", "Skip the fidelity floor (on the simulated rig: the best any algorithm "
                                             "could do through this rig, each side; a few hundred renders).")]
MaxMemory = Annotated[Optional[str], option(
    "--max-memory", metavar="SIZE", callback=_memory_check,
    help="Largest memory the run may need, e.g. 64G (default: what the machine has available now). The need is "
         "estimated from the scene before any work.")]
Cluster = Annotated[Optional[str], option(
    "--cluster", metavar="auto|local|ray://HOST:PORT",
    help="Spread the work over a Ray cluster (pip install 'lftransfer[cluster]'): auto (the cluster `ray start` "
         "made here, else a local one) | local (one started for this job) | ray://HOST:PORT. Results are "
         "bit-identical to one process (a quiet reference, split into one part per worker, to one process that "
         "splits it alike).")]
Workers = Annotated[Optional[int], option("--workers", min=1, metavar="N",
                                          help="Cluster workers (default: one per GPU, else per CPU core).")]
Recalibrate = Annotated[bool, flag("--recalibrate", (
    "Calibrate the simulated rig again although the calibration cache holds its calibration (the same scene "
    "devices, truth seed and code), and store the new one."))]
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
        "Which rig: sim (simulated, default) | hardware:RIG.toml (a physical rig, or the device twin; a scene of "
        "several light field interfaces: one rig file each, in its order, hardware:FRONT.toml,SIDE.toml) | "
        "replay:DIR (a recording)."))] = "sim"
    rig_model: Annotated[str, option(
        "--rig-model", metavar=metavar(choices.RigModel), callback=choice_check("--rig-model", choices.RigModel),
        help="What the pipeline knows of the rig: calibrated (calibrate through the rig first) | nominal (the rig "
             "file's values) | oracle (the simulated rig's hidden truth: what perfect calibration would reach).")
    ] = choices.DEFAULT_RIG_MODEL
    calibration: Calibration = None
    recalibrate: Recalibrate = False


class SettingOptions:
    """Base of the option groups :func:`setting_options` makes: the settings a command was given."""

    def overrides(self, *, compare_all: bool = False) -> Overrides:
        """The :class:`~lftransfer.settings.Overrides` these options ask for (a flag left off: None, the scene's);
        ``compare_all``: also measuring every other value of every comparable choice
        (:meth:`~lftransfer.settings.Overrides.comparing_all`)."""
        asked = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        if asked.get("quiet_reference") is False:
            asked["quiet_reference"] = None
        return Overrides.comparing_all(**asked) if compare_all else Overrides(**asked)

    def arguments(self) -> list[str]:
        """The options that give these settings, those left at their defaults left out (a command line that
        reproduces a run)."""
        parts: list[str] = []
        for f in dataclasses.fields(self):
            value, flag_name = getattr(self, f.name), _flag(f.name)
            if value != f.default:
                parts += ([flag_name] if value else [f"--no-{flag_name[2:]}"]) if isinstance(value, bool) \
                    else [flag_name, f"{value:g}" if isinstance(value, float) else str(value)]
        return parts


def _flag(name: str) -> str:
    """The option of ``Overrides``' field ``name``: its metadata's ``flag``, else the field's name
    (``--lighting-model``)."""
    return Overrides.__dataclass_fields__[name].metadata.get("flag") or "--" + name.replace("_", "-")


def _setting_field(name: str, default=None) -> tuple[str, object, object]:
    """(name, annotated type, default) of the option of ``Overrides``' field ``name``; ``default``: the command's
    own starting value where it is not the field's ``command_default`` (a flag that starts on is
    ``--x/--no-x``)."""
    spec = Overrides.__dataclass_fields__[name]
    meta, flag_name = spec.metadata, _flag(name)
    start = meta["command_default"] if default is None else default
    kind = next(a for a in get_args(get_type_hints(Overrides)[name]) if a is not type(None))
    if meta["choice"] is not None:
        info = option(flag_name, metavar=metavar(meta["choice"]), callback=choice_check(flag_name, meta["choice"]),
                      help=meta["help"])
        kind = str
    elif kind is bool:
        if start:
            return name, Annotated[bool, option(f"{flag_name}/--no-{flag_name[2:]}", metavar="",
                                                help=meta["help"])], True
        return name, Annotated[bool, flag(flag_name, meta["help"])], False
    else:
        info = option(flag_name, help=meta["help"], **meta["bounds"])
    return name, Annotated[kind if start is not None else Optional[kind], info], start


@functools.lru_cache(maxsize=None)
def setting_options(*names: str, defaults: tuple[tuple[str, object], ...] = ()) -> type:
    """An option group (:func:`option_groups`) of the settings ``names``, fields of
    :class:`~lftransfer.settings.Overrides`: each option's flag is the field's name (``--lighting-model``) or its
    metadata's ``flag``, its help, values and bounds are the field's, and the command receives a
    :class:`SettingOptions` whose :meth:`~SettingOptions.overrides` is what it asked for. ``defaults``: (name,
    value) where this command starts from another value than the field's ``command_default``.

    Example:
        >>> RunSettings = setting_options("bounces", "renderer", defaults=(("quiet_reference", True),))
        >>> def run(scene_file: SceneArg, asked: RunSettings = None) -> None: ...     # doctest: +SKIP
    """
    unknown = [n for n in (*names, *dict(defaults)) if n not in Overrides.__dataclass_fields__ or n == "compare"]
    if unknown:
        raise ValueError(f"not a setting of Overrides: {', '.join(unknown)}")
    starts = dict(defaults)
    fields = [(name, kind, dataclasses.field(default=default))
              for name, kind, default in (_setting_field(n, starts.get(n)) for n in names)]
    return dataclasses.make_dataclass("Settings_" + "_".join(names), fields, bases=(SettingOptions,), frozen=True)


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
