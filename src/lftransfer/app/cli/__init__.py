"""The ``lft`` command.

Everything that can be checked before the work starts is checked first: options and their ranges, the scene
file, a calibration file, the output paths, the ground-truth cache folder and the memory the run needs
(:mod:`lftransfer.runs.paths`, :mod:`lftransfer.runs.memory`). Errors are one line on stderr with exit code 2 for
bad input (:mod:`lftransfer.app.terminal`); ``lft --debug ...`` shows tracebacks.

One module per command group: :mod:`~lftransfer.app.cli.run` (demo, run, record),
:mod:`~lftransfer.app.cli.sequence` (render, live), :mod:`~lftransfer.app.cli.study`,
:mod:`~lftransfer.app.cli.bench`, :mod:`~lftransfer.app.cli.calibrate`, :mod:`~lftransfer.app.cli.twin`; the
options they share are defined once in :mod:`~lftransfer.app.cli.options`. docs/cli.md is generated from them.
"""

from __future__ import annotations

import logging
from typing import Annotated, Optional

import typer

from lftransfer import backend, choices
from lftransfer.app.cli import bench, depth, run, sequence, study
from lftransfer.app.cli.calibrate import calibrate_app
from lftransfer.app.cli.common import Group
from lftransfer.app.cli.options import flag, option
from lftransfer.app.cli.new import new_app
from lftransfer.app.cli.sim import sim_app
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
                                                help="Show the version and exit.")] = False,
          blas_threads: Annotated[Optional[int], option(
              "--blas-threads", metavar="N", min=0,
              help=f"Threads of NumPy's, SciPy's and OpenCV's BLAS beside the renderer (default "
                   f"${backend.BLAS_THREADS_ENV} or {choices.DEFAULT_BLAS_THREADS}; 0: the libraries' own, one "
                   f"per core). More than one takes cores from the renderer: docs/performance.md.")] = None,
          ) -> None:
    """Light field transfer between real and synthetic objects."""
    try:
        if blas_threads is not None:
            backend.set_blas_threads(blas_threads)
        else:
            backend.blas_threads()          # a bad $LFT_BLAS_THREADS is refused here, in one line
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="'--blas-threads'") from None


run.register(app)
sequence.register(app)
study.register(app)
bench.register(app)
depth.register(app)
app.add_typer(calibrate_app, name="calibrate")
app.add_typer(twin_app, name="twin")
app.add_typer(sim_app, name="sim")
app.add_typer(new_app, name="new")


def main() -> None:  # pragma: no cover
    logging.basicConfig(level=logging.WARNING)
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
