"""What ``lft live`` (:mod:`lftransfer.app.cli`) opens: a live session of a scene on a rig."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

from lftransfer.choices import DEFAULT_LIVE_LOOP, DEFAULT_RIG_MODEL
from lftransfer.settings import Overrides

__all__ = ["open_session"]


def open_session(scene, *, rig: str = "sim", rig_model: str = DEFAULT_RIG_MODEL, calibration: Optional[Path] = None,
                 recalibrate: bool = False,
                 truth_seed: Optional[int] = 0, out: Path = Path("out/live"), settings: Overrides = Overrides(),
                 loop: str = DEFAULT_LIVE_LOOP, progress=None, warn=None):
    """A :class:`~lftransfer.app.viewer.session.LiveSession` for a scene on a rig: the rig opened, its model had
    (calibrated, a calibration file, nominal or oracle), the live loop built with the scene's render settings and
    ``settings`` (what the command asked for; the page's edits change them), decoupled (captures at the devices'
    rate) or synchronous (``loop``)."""
    from lftransfer.runs.pipeline import RunOptions
    from lftransfer.runs.rigs import RigSpec, open_rig
    from lftransfer.runs.sequence import acquire_model
    from lftransfer.app.viewer.session import LiveSession
    from lftransfer.transfer.live import LiveTransfer

    out = Path(out)
    options = RunOptions(rig=RigSpec.parse(rig), rig_model=rig_model, calibration=calibration, truth_seed=truth_seed,
                         settings=settings, recalibrate=recalibrate)
    resolved = options.resolve(scene, live=True, loop=loop)
    opened = open_rig(scene, options, simulator=resolved.simulator, interfaces=True)
    known = acquire_model(opened, scene, options, out, False, progress or (lambda _m: None))
    for note in known.warnings:
        (warn or (lambda _m: None))(note)
    for note in resolved.adjustments:
        (warn or (lambda _m: None))(note)
    live = LiveTransfer(opened.rig, known.model, known.scene, resolved.transfer, loop=loop, turns=opened.turns,
                        rigs=opened.rigs, models=known.models)
    sim = opened.rig if hasattr(opened.rig, "place_real") else None     # moves them for every interface
    return LiveSession(scene, live, out, sim_rig=sim, oracle=opened.oracle, lights=known.scene.lights,
                       overrides=options.settings)
