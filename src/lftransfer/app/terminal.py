"""How the ``lft`` command talks to the terminal: one line per error on stderr, exit codes, ``--debug``.

Every error of the command line is one line on stderr that starts with ``error:``. Exit codes:

- 0: done;
- 1: the work failed (a rig fault, an internal error);
- 2: bad input (an option, a scene, rig or calibration file, an output path, a run too big for the memory);
- 130: interrupted (Ctrl-C).

A traceback is shown only with ``lft --debug ...`` (``--debug`` may stand anywhere before a ``--``). Text that
comes from the user (file names, messages quoting a file) is escaped before it reaches rich, so
``take[v2].toml`` and ``[[real]]`` are shown as written. Python warnings are shown as one ``warning:`` line.
"""

from __future__ import annotations

import sys
import warnings
from contextlib import contextmanager
from typing import Any, Iterator, NoReturn, Sequence

import typer
from rich.console import Console
from rich.markup import escape
from typer.core import TyperGroup

__all__ = ["BAD_INPUT", "INTERRUPTED", "FAILED", "LftGroup", "console", "fail", "input_error_types", "one_line",
           "say", "warn"]

FAILED, BAD_INPUT, INTERRUPTED = 1, 2, 130

console = Console(stderr=True)


def _click_base(name: str) -> type:
    """A class of the click that typer uses (typer vendors click in recent versions), found by name."""
    for cls in typer.BadParameter.__mro__:
        if cls.__name__ == name:
            return cls
    raise ImportError(f"typer's click has no {name}")  # pragma: no cover


ClickException = _click_base("ClickException")
UsageError = _click_base("UsageError")


def one_line(text: object) -> str:
    """``text`` as one line: line breaks and runs of blanks become single spaces."""
    return " ".join(str(text).split())


def fail(message: str, code: int = BAD_INPUT) -> NoReturn:
    """Print ``error: message`` (one line, escaped) on stderr and leave with ``code`` (2: bad input)."""
    console.print(f"[bold red]error:[/] {escape(one_line(message))}", soft_wrap=True, highlight=False)
    raise typer.Exit(code=code)


def warn(message: str) -> None:
    """Print ``warning: message`` (one line, escaped) on stderr."""
    console.print(f"[bold yellow]warning:[/] {escape(one_line(message))}", soft_wrap=True, highlight=False)


def say(message: str) -> None:
    """Print a plain message (escaped) on stderr."""
    console.print(escape(one_line(message)), soft_wrap=True, highlight=False)


def input_error_types() -> tuple[type, ...]:
    """Exceptions that mean bad input: the project's file and option errors (exit code 2)."""
    from lftransfer.runs.memory import MemoryLimitError
    from lftransfer.runs.paths import OutputPathError
    from lftransfer.imageio_utils import ImageReadError
    from lftransfer.calibration.intrinsics import IntrinsicsError
    from lftransfer.calibration.rig import CalibrationFileError
    from lftransfer.rig.hardware.config import RigFileError
    from lftransfer.scenes import SceneError

    return (SceneError, CalibrationFileError, RigFileError, ImageReadError, IntrinsicsError,
            OutputPathError, MemoryLimitError)


def _take_debug(args: list[str]) -> tuple[list[str], bool]:
    """Remove every ``--debug`` before a ``--`` from the arguments; whether there was one."""
    end = args.index("--") if "--" in args else len(args)
    kept = [a for a in args[:end] if a != "--debug"]
    return kept + args[end:], len(kept) < end


@contextmanager
def _one_line_warnings() -> Iterator[None]:
    """Show Python warnings as ``warning: <message>`` lines (once per message and place)."""
    previous = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ANN001
        warn(f"{message} ({category.__name__})")

    warnings.showwarning = show
    try:
        yield
    finally:
        warnings.showwarning = previous


class LftGroup(TyperGroup):
    """The ``lft`` group: runs a command and turns every way it can end into an exit code and at most one line.

    ``lft --debug ...`` lets unexpected exceptions through with their traceback instead.
    """

    def main(self, args: Sequence[str] | None = None, prog_name: str | None = None,
             complete_var: str | None = None, standalone_mode: bool = True, **extra: Any) -> Any:
        args, debug = _take_debug(list(sys.argv[1:] if args is None else args))
        if debug:
            args = ["--debug", *args]
        code = self._run(args, prog_name or "lft", debug, extra)
        if standalone_mode:
            sys.exit(code)
        return code

    def _run(self, args: list[str], prog_name: str, debug: bool, extra: dict) -> int:
        try:
            with _one_line_warnings():
                with self.make_context(prog_name, args, **extra) as ctx:
                    self.invoke(ctx)
            return 0
        except typer.Exit as exc:
            return exc.exit_code
        except (KeyboardInterrupt, EOFError, typer.Abort):
            say("interrupted")
            return INTERRUPTED
        except ClickException as exc:
            if type(exc).__name__ == "NoArgsIsHelpError":        # ``lft`` or ``lft calibrate`` alone: the help
                if exc.format_message().strip():                  # (rich has printed it already)
                    typer.echo(exc.format_message())
                return exc.exit_code
            where = ""
            if isinstance(exc, UsageError) and exc.ctx is not None:
                where = f" (see '{exc.ctx.command_path} --help')"
            return self._error(f"{exc.format_message()}{where}", exc.exit_code)
        except BrokenPipeError:
            return FAILED
        except Exception as exc:  # noqa: BLE001 - the last line of defence: one line, unless --debug
            if debug:
                raise
            if isinstance(exc, input_error_types()):
                return self._error(str(exc), BAD_INPUT)
            return self._error(f"{type(exc).__name__}: {exc} (lft --debug ... shows the traceback)", FAILED)

    @staticmethod
    def _error(message: str, code: int) -> int:
        try:
            fail(message, code)
        except typer.Exit as exc:
            return exc.exit_code
        return code  # pragma: no cover
