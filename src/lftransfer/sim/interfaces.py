"""The simulated world with several light field interfaces (docs/architecture.md, "Several interfaces").

One :class:`~lftransfer.sim.rig.SimRig` per interface, each a whole :class:`~lftransfer.rig.Rig` (its LF camera, its
projector, the shared view camera), all facing the same real objects: each interface's projector lights them, each
LF camera sees them and, where it looks at another interface's lenslets, what that one projects. So light that
leaves the synthetic side through one interface and comes back through another is carried as a real rig carries
it.
"""

from __future__ import annotations

from lftransfer.rig.model import RigModel
from lftransfer.sim.rig import SimRig

__all__ = ["SimInterfaces"]


class SimInterfaces:
    """Every interface of a scene, simulated in one world.

    Args:
        scene: the scene (``SceneConfig``; its ``[[interface]]`` tables, or ``[rig]`` alone for one interface).
        truths: the true rig model of each interface (:func:`lftransfer.sim.truth.true_interfaces`); None: each
            interface's nominal model.
        **kwargs: :class:`~lftransfer.sim.rig.SimRig`'s other arguments, the same for every interface.

    Attributes:
        rigs: one rig per interface, in the scene's order.
    """

    def __init__(self, scene, *, truths: list[RigModel] | None = None, **kwargs) -> None:
        n = max(1, len(scene.interfaces))
        if truths is not None and len(truths) != n:
            raise ValueError(f"SimInterfaces: {len(truths)} true rig models for {n} interfaces")
        self.rigs = [SimRig(scene, truth=None if truths is None else truths[i], interface=i, **kwargs)
                     for i in range(n)]
        if n > 1:
            for rig in self.rigs:
                rig.join(self.rigs)

    @property
    def truths(self) -> list[RigModel]:
        """The hidden true rig model of each interface (verification only)."""
        return [r.truth for r in self.rigs]

    def place_real(self, objects) -> None:
        """Put the real objects somewhere else, for every interface (:meth:`SimRig.place_real` moves them in the
        world all the joined rigs share)."""
        self.rigs[0].place_real(objects)

    def start_frame(self, index: int) -> None:
        """Begin frame ``index`` of an independent sequence on every interface (:meth:`SimRig.start_frame`)."""
        for rig in self.rigs:
            rig.start_frame(index)

    def close(self) -> None:
        for rig in self.rigs:
            rig.close()
