"""``lft live SCENE.toml``: the live loop and its page (registered on the ``lft`` command in :mod:`lftransfer.app.cli`)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

__all__ = ["live_cmd", "open_session"]


def open_session(scene, *, rig: str = "sim", rig_model: str = "calibrated", calibration: Optional[Path] = None,
                 truth_seed: Optional[int] = 0, out: Path = Path("out/live"), renderer: str = "auto",
                 progress=None):
    """A :class:`~lftransfer.app.viewer.session.LiveSession` for a scene on a rig: the rig opened, its model had
    (calibrated, a calibration file, nominal or oracle), the live loop built with the scene's render settings."""
    from lftransfer.app.pipeline import RigSpec, RunOptions, open_rig
    from lftransfer.app.sequence import acquire_model
    from lftransfer.app.viewer.session import LiveSession
    from lftransfer.transfer.bounce import TransferSettings
    from lftransfer.transfer.live import LiveTransfer

    out = Path(out)
    options = RunOptions(rig=RigSpec.parse(rig), rig_model=rig_model, calibration=calibration, truth_seed=truth_seed,
                         renderer=renderer)
    opened = open_rig(scene, options)
    model, _ = acquire_model(opened, scene, options, out, False, progress or (lambda _m: None))
    r = scene.render
    settings = TransferSettings(angular_samples=scene.rig.angular_samples, lighting_model=r.lighting_model,
                                aperture_samples=r.aperture_samples,
                                reconstruction=r.reconstruction if r.lighting_model == "area" else "box",
                                lf_spp=r.spp, view_spp=r.spp, renderer=renderer)
    live = LiveTransfer(opened.rig, model, scene.synthetic_part(), settings)
    sim = opened.rig if hasattr(opened.rig, "place_real") else None
    return LiveSession(scene, live, out, sim_rig=sim)


def live_cmd(scene_file: Path = typer.Argument(..., metavar="SCENE.toml", help="Scene TOML file."),
             rig: str = typer.Option("sim", metavar="SPEC", help=(
                 "Which rig: sim (simulated, default) | hardware:RIG.toml (a physical rig) | replay:DIR.")),
             port: int = typer.Option(8080, min=1, max=65535, metavar="PORT", help="Port of the page on localhost."),
             out: Path = typer.Option(Path("out/live"), metavar="DIR", help="Where 'save' writes frames and scenes."),
             quick: bool = typer.Option(False, "--quick", help="Quarter resolution (devices, angular samples)."),
             rig_model: str = typer.Option("calibrated", metavar="calibrated|nominal|oracle", help=(
                 "What the pipeline knows of the rig (oracle: the simulated rig's truth).")),
             calibration: Optional[Path] = typer.Option(None, metavar="FILE", help=(
                 "Use this calibration file instead of calibrating.")),
             renderer: str = typer.Option("auto", metavar="auto|fast|exact", help="Synthetic renderer.")) -> None:
    """Run the live loop and show it on a page at http://127.0.0.1:PORT/ until Ctrl-C: the composite, the
    layers, the light field images, the time of every stage; move and edit the synthetic objects (and the real
    ones on the simulated rig)."""
    from lftransfer.app.cli import _load
    from lftransfer.app.terminal import console, fail
    from lftransfer.app.viewer.server import serve

    if rig_model not in ("calibrated", "nominal", "oracle"):
        fail(f"--rig-model: expected calibrated, nominal or oracle, got {rig_model!r}")
    if calibration is not None and not calibration.is_file():
        fail(f"--calibration {calibration}: no such file")
    scene = _load(scene_file, quick)
    with console.status("setting up the rig (calibrating first takes minutes at full resolution)") as status:
        session = open_session(scene, rig=rig, rig_model=rig_model, calibration=calibration, out=out,
                               renderer=renderer, progress=lambda msg: status.update(msg[:70]))
    console.print(f"lft live: open http://127.0.0.1:{port}/ (Ctrl-C stops)")
    serve(session, port=port)
    console.print("lft live: stopped")
