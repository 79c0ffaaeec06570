"""The bounce loop through several light field interfaces (docs/architecture.md, "Several interfaces").

The same exchange as :func:`lftransfer.transfer.bounce.run_transfer`, through every interface at once. Each interface
is a whole rig (its LF camera, its projector, the shared view camera) with its own model; the synthetic side is one
renderer lit by every interface's captured light field together, each posed where its array stands, and it renders
the light field it sends towards each array:

- direct: every projector black; R_0^i = decode_i(capture_i) for every interface i; Ls_0^i and S_0 with the virtual
  point lights (and the depth each interface measures with its own projector white, where the projection needs it);
- bounce n >= 1: every projector shows encode_i(g Ls_{n-1}^i) at once, one gain g for all (the smallest that keeps
  every projector in range), so that R_n^i = (decode_i(capture_i) - R_0^i) / g is the real scene's response to all of
  them, light that leaves through one array and comes back through another included; Ls_n^i and S_n with the
  synthetic scene lit by every R_{n-1}^i;
- final frame: every projector shows its sum Ls_0^i + ... + Ls_{N-1}^i while the view camera captures.

An interface switched off (``through``) keeps its projector black and its capture unused: its array still stands
there, as the same rig with that interface idle would.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from lftransfer.backend import bound_blas
from lftransfer.render.base import ViewImage
from lftransfer.rig.base import Rig
from lftransfer.rig.model import RigModel
from lftransfer.rig.requests import RealScene
from lftransfer.scenes import SyntheticScene
from lftransfer.transfer.bounce import Bounce, TransferResult, TransferSettings, final_projection, projector_gain
from lftransfer.transfer.projection import measure_depth
from lftransfer.transfer.synthetic_side import SyntheticSide, render_sides
from lftransfer.transfer.timer import StageTimer

__all__ = ["count_interface_steps", "run_interfaces", "transfer_through"]


def count_interface_steps(settings: TransferSettings, interfaces: int) -> int:
    """Number of progress callbacks :func:`run_interfaces` makes through ``interfaces`` interfaces."""
    return 3 + (interfaces if settings.prefilters else 0) + 2 * settings.bounces


def transfer_through(rigs: Sequence[Rig], models: Sequence[RigModel], scene: SyntheticScene,
                     settings: TransferSettings = TransferSettings(), *,
                     progress: Callable[[str], None] | None = None, time_s: float = 0.0, **one) -> TransferResult:
    """N bounces through one interface (:func:`~lftransfer.transfer.bounce.run_transfer`, ``rigs`` and ``models``
    of one) or several (:func:`run_interfaces`): what a converged sequence, its exchange check and the page's bounce
    layers run. ``one``: :func:`~lftransfer.transfer.bounce.run_transfer`'s further arguments (a depth measured
    earlier, ``depth`` and ``view_depth``), for one interface; several measure each interface's depth themselves."""
    from lftransfer.transfer.bounce import run_transfer

    if len(rigs) == 1 and len(models) == 1:
        return run_transfer(rigs[0], models[0], scene, settings, progress=progress, time_s=time_s, **one)
    return run_interfaces(rigs, models, scene, settings, progress=progress, time_s=time_s)


def run_interfaces(rigs: Sequence[Rig], models: Sequence[RigModel], scene: SyntheticScene,
                   settings: TransferSettings = TransferSettings(), *, through: Sequence[int] | None = None,
                   progress: Callable[[str], None] | None = None, time_s: float = 0.0) -> TransferResult:
    """N bounces of light field transfer through several interfaces.

    Args:
        rigs: one rig per interface, in the scene's order, sharing one real world (their view cameras are one:
            the first's is used).
        models: what the pipeline knows of each interface (its array placed in the world: ``RigModel.placement``).
        scene: the synthetic part of the scene.
        settings: as for :func:`~lftransfer.transfer.bounce.run_transfer`; the over composite only.
        through: the interfaces that exchange light (indices); None: all. The others stay dark.
        progress: called with a short description at the start of each step.
        time_s: the moment of an animated scene.

    Returns:
        TransferResult: the synthetic view, the final real view and composite, and each interface's bounces
        (:attr:`~lftransfer.transfer.bounce.TransferResult.interfaces`).
    """
    step = progress or (lambda _msg: None)
    if len(rigs) != len(models) or not rigs:
        raise ValueError(f"run_interfaces: {len(rigs)} rigs for {len(models)} rig models")
    used = sorted(set(range(len(rigs)) if through is None else through))
    if not used or not set(used) <= set(range(len(rigs))):
        raise ValueError(f"through: expected interfaces among 0..{len(rigs) - 1}, got {list(through or [])}")
    if settings.composite != "over":
        raise ValueError("several interfaces composite with the over operator (composite = 'over'); the depth "
                         "composite measures one interface's depth")
    bound_blas()
    loop = _Exchange(list(rigs), list(models), SyntheticSide.through(models, scene, settings, time_s=time_s), used,
                     settings, step, StageTimer())
    bounces, views, raw0, real_view_direct = loop.direct(time_s)
    for n in range(1, settings.bounces + 1):
        views.append(loop.bounce(n, bounces, real_view_direct))
    step("final frame: every projector shows its sum of the synthetic light fields")
    projected = {i: final_projection(bounces[i]) for i in used}
    patterns, real_view = loop.final(projected, real_view_direct)
    lit = np.concatenate([projected[i].data[projected[i].data > 0] for i in used])
    clipped = float(np.mean(lit > min(models[i].projector.max_radiance for i in used))) if lit.size else 0.0
    s0 = views[0]
    synthetic_view = ViewImage(rgb=sum(v.rgb for v in views).astype(np.float32), alpha=s0.alpha, depth=s0.depth)
    main = used[0]
    return TransferResult(
        bounces=bounces[main], real_view=real_view, real_view_direct=real_view_direct, synthetic_view=synthetic_view,
        projected_image=patterns[main], projected_lf=projected[main], clipped_fraction=clipped,
        captured_raw=raw0[main],
        saturated_fraction=float(np.mean(raw0[main] >= 2 ** rigs[main].info.lf_camera_bits - 1)),
        timings_s=loop.timer.totals,
        interfaces=tuple(bounces.get(i) for i in range(len(rigs))), projected_images=tuple(patterns[i] for i in used),
        captured_raws=tuple(raw0[i] for i in used))


@dataclass
class _Exchange:
    """The steps of :func:`run_interfaces` over the exchanging interfaces ``used``."""

    rigs: list
    models: list
    sides: list[SyntheticSide]
    used: list[int]
    settings: TransferSettings
    step: Callable[[str], None]
    timer: StageTimer
    r0: dict = field(default_factory=dict)      # each exchanging interface's R_0, once captured

    def direct(self, time_s: float):
        """Every projector black: each R_0^i (and depth), Ls_0^i and S_0. Returns (each interface's bounces so
        far, the synthetic views so far, each direct capture's codes, the direct real view)."""
        rigs, sides, used, s, timer = self.rigs, self.sides, self.used, self.settings, self.timer
        self.step("capture direct (every projector black)")
        for rig in rigs:
            rig.setup(RealScene(time_s=time_s))
            rig.project(rig.info.black())
        with timer("capture"):
            raw0 = {i: rigs[i].capture_lf().codes for i in used}
        with timer("capture_view"):
            real_view_direct = rigs[0].capture_view().radiance
        with timer("decode"):
            self.r0 = {i: sides[i].decoder(raw0[i]) for i in used}
        if s.prefilters:
            for i in used:
                self.step(f"interface {i}: measure the real scene's depth (its projector white)")
                with timer("measure_depth"):
                    swept = measure_depth(rigs[i], sides[i].decoder, sides[i].encoder,
                                          self.models[i].projector.max_radiance, s.angular_samples,
                                          s.angular_samples, self.r0[i])
                sides[i].set_depth(swept.depth)
                rigs[i].project(rigs[i].info.black())
        self.step("render synthetic direct")
        ls, s0 = render_sides(sides, sides[0].direct_lights, s.seed, timer, used=used)
        bounces = {i: [Bounce(0, self.r0[i], ls[i], s0 if i == used[0] else None, real_view=real_view_direct)]
                   for i in used}
        return bounces, [s0], raw0, real_view_direct

    def bounce(self, n: int, bounces: dict, real_view_direct: np.ndarray) -> ViewImage:
        """Bounce n: every projector shows its Ls_{n-1}^i at one gain, every response captured; the synthetic side
        lit by every R_{n-1}^i. Appends to ``bounces``; returns S_n."""
        rigs, sides, used, s, timer = self.rigs, self.sides, self.used, self.settings, self.timer
        prev = {i: bounces[i][n - 1] for i in used}
        gain = min(projector_gain(prev[i].synthetic_lf, self.models[i].projector.max_radiance, s.projector_fill)
                   for i in used)
        self.step(f"bounce {n}: every projector shows its Ls_{n - 1} (gain {gain:.3g}); capture every response")
        for i in used:
            with timer("encode"):
                rigs[i].project(sides[i].encoder(prev[i].synthetic_lf * gain))
        with timer("capture"):
            raws = {i: rigs[i].capture_lf().codes for i in used}
        with timer("decode"):
            rn = {i: (sides[i].decoder(raws[i]) - self.r0[i]) / gain for i in used}
        real_view_n = None
        if s.bounce_views:
            with timer("capture_view"):
                real_view_n = (rigs[0].capture_view().radiance - real_view_direct) / gain
        self.step(f"bounce {n}: render synthetic lit by every R_{n - 1}")
        with timer("incident_light"):
            lights = [sides[i].incident_light(prev[i].real_lf, s.seed + n + 7 * i) for i in used]
        ls, sn = render_sides(sides, lights, s.seed + 1000 * n, timer, used=used)
        for i in used:
            bounces[i].append(Bounce(n, rn[i], ls[i], sn if i == used[0] else None, real_view=real_view_n,
                                     projector_gain=gain))
        return sn

    def final(self, projected: dict, real_view_direct: np.ndarray) -> tuple[dict, np.ndarray]:
        """Every projector shows its sum while the view camera captures (none with no bounce): (each projector
        image, the real view)."""
        rigs, timer = self.rigs, self.timer
        patterns = {}
        for i in self.used:
            with timer("encode"):
                patterns[i] = self.sides[i].encoder(projected[i]) if self.settings.bounces else rigs[i].info.black()
            rigs[i].project(patterns[i])
        with timer("capture_view"):
            real_view = rigs[0].capture_view().radiance if self.settings.bounces else real_view_direct
        for i in self.used:
            rigs[i].project(rigs[i].info.black())
        return patterns, real_view
