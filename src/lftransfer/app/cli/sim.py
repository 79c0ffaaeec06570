"""``lft sim``: the simulated rig's own images on disk: its photographs (``capture``), to try the calibration steps that
read image files, and test light fields of known depth (``views``), for ``lft depth``. The captures themselves are
:mod:`lftransfer.runs.captures` and :mod:`lftransfer.sim.views`; this module is their face."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from rich.console import Console
from rich.markup import escape

from lftransfer.app.cli.common import command, load, sub_app
from lftransfer.app.cli.options import Quick, SceneArg, TruthArgs, flag, option
from lftransfer.app.terminal import fail

sim_app = sub_app(name="sim", help="The simulated rig's own photographs on disk, to try the calibration steps that "
                                   "read image files (lft calibrate lenslets) without hardware, and test light "
                                   "fields of known depth for lft depth.")

KIND_HELP = ("spots: the LF camera under a collimated on-axis source (for lft calibrate lenslets) | white: under the "
             "white diffuser (lft calibrate lenslets --kind white) | scene: the LF camera and the view camera on the "
             "real scene, projector black.")


@command(sim_app, "capture")
def capture(scene_file: SceneArg,
            kind: Annotated[str, option("--kind", metavar="spots|white|scene", help=KIND_HELP)] = "spots",
            out: Annotated[Path, option("--out", metavar="DIR", help=(
                "Folder for the images: lf_KIND.png (16-bit PNG of the LF camera's codes), view.exr and view.png "
                "(scene), truth_centres.csv (--truth); made if missing."))] = Path("out/sim"),
            truth_file: Annotated[bool, flag("--truth", "Also write the simulated rig's true lenslet centres in the "
                                                        "LF camera (truth_centres.csv, the CSV lft calibrate "
                                                        "lenslets writes), to compare its result with.")] = False,
            quick: Quick = False, truth: TruthArgs = None) -> None:
    """Photograph the simulated rig of a scene (a collimated source, the white diffuser or the real scene) and write
    the images as a physical rig's cameras would leave them."""
    from lftransfer.runs.captures import KINDS, capture_images
    from lftransfer.runs.paths import check_output_dir

    if kind not in KINDS:
        fail(f"--kind: expected one of {', '.join(KINDS)}, got {kind!r}")
    scene = load(scene_file, quick)
    check_output_dir(out)
    written = capture_images(scene, kind, out, truth_seed=truth.seed, truth=truth_file)
    for path in written:
        Console().print(escape(f"wrote {path}"), soft_wrap=True, highlight=False)
    if kind in ("spots", "white"):
        lattice = scene.rig.lattice
        hint = f"lft calibrate lenslets {written[0]} --lattice {lattice}" + (" --kind white" if kind == "white" else "")
        Console().print(escape(f"try: {hint} --out {out / 'centres.csv'}"), soft_wrap=True, highlight=False)


@command(sim_app, "views")
def views(scene_file: SceneArg,
          out: Annotated[Path, option("--out", metavar="DIR", help=(
              "Folder for the light field: input_CamNNN.png (16-bit grey, row-major) and parameters.cfg as the 4D "
              "light field benchmark lays them out, gt_disp_lowres.pfm (the centre view's true disparity, pixels "
              "per view step) and gt_depth_lowres.pfm (its true depth, metres); made if missing."))
          ] = Path("out/views"),
          n: Annotated[int, option("--views", min=3, metavar="N", help="Views per side (odd).")] = 9,
          baseline_mm: Annotated[float, option("--baseline-mm", min=0.01, metavar="MM", help=(
              "Distance between neighbouring cameras, mm."))] = 2.0,
          spp: Annotated[int, option("--spp", min=1, metavar="N", help="Rays per pixel.")] = 16,
          quick: Quick = False, truth: TruthArgs = None) -> None:
    """Render a test light field of known depth: a grid of views of the scene's real objects around its view camera,
    through the simulated rig (its hidden truth), for lft depth."""
    from lftransfer.lightfield.view_grid import write_pfm, write_view_grid
    from lftransfer.runs.paths import check_output_dir
    from lftransfer.sim.views import render_view_grid

    if n % 2 == 0:
        fail(f"--views {n}: expected an odd number (the centre view is the scene's view camera)")
    scene = load(scene_file, quick)
    check_output_dir(out)
    grid, disparity, depth = render_view_grid(scene, n=n, baseline_m=baseline_mm / 1000.0, spp=spp,
                                              truth_seed=truth.seed)
    written = [write_view_grid(out, grid), write_pfm(out / "gt_disp_lowres.pfm", disparity),
               write_pfm(out / "gt_depth_lowres.pfm", depth)]
    for path in written:
        Console().print(escape(f"wrote {path}"), soft_wrap=True, highlight=False)
    Console().print(escape(f"try: lft depth {out} --truth {out / 'gt_disp_lowres.pfm'} --out {out / 'depth'}"),
                    soft_wrap=True, highlight=False)
