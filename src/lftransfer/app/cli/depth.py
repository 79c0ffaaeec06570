"""``lft depth DIR --out OUT``: the disparity and depth of any 4D light field given as a folder of sub-aperture
views (:mod:`lftransfer.runs.depth`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from lftransfer.app.cli.common import command, row
from lftransfer.app.cli.options import option
from lftransfer.app.terminal import fail


def depth(folder: Annotated[Path, typer.Argument(metavar="DIR", help=(
              "A light field folder: N x N views input_CamNNN.png (row-major) and parameters.cfg, as the 4D light "
              "field benchmark lays one out."))],
          out: Annotated[Path, option("--out", metavar="DIR", help=(
              "Output folder (made if missing): disparity.pfm (pixels per view step, the benchmark's sign: "
              "positive nearer than the focus plane), depth.pfm (metres), a PNG of each, confidence.png, "
              "report.json."))] = Path("out/depth"),
          truth: Annotated[Optional[Path], option("--truth", metavar="FILE.pfm", help=(
              "A ground-truth disparity map: report the benchmark's BadPix 0.07 (percent of pixels off by more "
              "than 0.07) and 100 x the mean squared error, 15 pixels at each side left out."))] = None,
          steps: Annotated[int, option("--steps", min=3, metavar="N", help=(
              "Candidate disparities over the folder's disp_min to disp_max."))] = 64) -> None:
    """Estimate the disparity and depth of a light field given as sub-aperture views: an occlusion-aware plane
    sweep over a cost volume filtered edge-aware (docs/architecture.md, "Occlusion")."""
    from lftransfer.lightfield.view_grid import ViewGridError
    from lftransfer.runs.depth import estimate_folder
    from lftransfer.runs.paths import check_output_dir

    if truth is not None and not truth.is_file():
        fail(f"--truth {truth}: no such file")
    check_output_dir(out)
    try:
        with Console(stderr=True).status("estimating the disparity"):
            report = estimate_folder(folder, out, truth=truth, steps=steps)
    except ViewGridError as exc:
        fail(str(exc))
    table = Table(title=escape(f"lft depth -> {out}"))
    table.add_column("key")
    table.add_column("value", justify="right")
    row(table, "views", " x ".join(map(str, report["views"])))
    row(table, "seconds", f"{report['seconds']:.1f}")
    if report["depth_m"] is not None:
        row(table, "depth_m", f"{report['depth_m'][0]:.3g} .. {report['depth_m'][1]:.3g}")
    for key, value in (report["scores"] or {}).items():
        row(table, f"scores.{key}", f"{value:.4g}" if isinstance(value, float) else str(value))
    Console().print(table)


def register(app: typer.Typer) -> None:
    """Add ``depth`` to ``app``."""
    command(app)(depth)
