"""The ``lft`` command.

Everything that can be checked before the work starts is checked first: options and their ranges, the scene
file, a calibration file, the output paths, the ground-truth cache folder and the memory the run needs
(:mod:`lftransfer.app.paths`, :mod:`lftransfer.app.memory`). Errors are one line on stderr with exit code 2 for
bad input (:mod:`lftransfer.app.terminal`); ``lft --debug ...`` shows tracebacks.

One module per command group: :mod:`~lftransfer.app.cli.run` (demo, run, record),
:mod:`~lftransfer.app.cli.sequence` (render, live), :mod:`~lftransfer.app.cli.study`,
:mod:`~lftransfer.app.cli.bench`, :mod:`~lftransfer.app.cli.calibrate`, :mod:`~lftransfer.app.cli.twin`; the
options they share are defined once in :mod:`~lftransfer.app.cli.options`. docs/cli.md is generated from them.
"""

from __future__ import annotations

import logging
from typing import Annotated

import typer

from lftransfer.app.cli import bench, run, sequence, study
from lftransfer.app.cli.calibrate import calibrate_app
from lftransfer.app.cli.common import Group
from lftransfer.app.cli.options import flag
from lftransfer.app.cli.twin import twin_app

__all__ = ["app", "main"]

app = typer.Typer(cls=Group, add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="Light field transfer between real and synthetic objects. Errors are one line on stderr "
                       "(exit code 2 for bad input, 1 for a failure, 130 when interrupted).")


def _version(value: bool) -> None:
    if value:
        from importlib.metadata import PackageNotFoundError, version

        try:
            typer.echo(f"lft (lftransfer) {version('lftransfer')}")
        except PackageNotFoundError:
            typer.echo("lft (lftransfer) not installed as a package")
        raise typer.Exit()


@app.callback()
def _main(debug: Annotated[bool, flag("--debug", "Show the Python traceback of an unexpected error (may stand "
                                                 "anywhere on the command line).")] = False,
          version: Annotated[bool, typer.Option("--version", metavar="", callback=_version, is_eager=True,
                                                help="Show the version and exit.")] = False) -> None:
    """Light field transfer between real and synthetic objects."""


run.register(app)
sequence.register(app)
study.register(app)
bench.register(app)
app.add_typer(calibrate_app, name="calibrate")
app.add_typer(twin_app, name="twin")


def main() -> None:  # pragma: no cover
    logging.basicConfig(level=logging.WARNING)
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
