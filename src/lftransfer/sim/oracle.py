"""The oracle: everything a run may learn of the simulated rig's hidden truth, and only after the fact.

The pipeline calibrates and transfers through the ``Rig`` interface alone. What it does not know (the world as
it is, the rig as it was built, where the lights really stand) stays here; the faces (``lftransfer.app``) ask an
opened rig for its optional :class:`Oracle` to verify a run (the ground truth, the metrics against it, the
calibration's errors) or to run a baseline (``--rig-model oracle``). An import contract in ``pyproject.toml``
says that the faces read the truth through this module only (docs/architecture.md, "The simulator").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from lftransfer.choices import DEFAULT_CAPTURE_SPP
from lftransfer.rig.model import RigModel, nominal_rig

__all__ = ["Oracle", "hidden_oracle", "one_interface", "open_simulated_interfaces", "open_simulated_rig",
           "oracle_of_recording"]


@dataclass(frozen=True)
class Oracle:
    """The hidden truth behind a simulated rig (or a recording made on one).

    Attributes:
        world: the scene as it really is (real and synthetic objects, lights where they stand, animation).
        model: the rig model as the rig was built (the rig file's own values where the truth is exact).
        truth_seed: the seed the truth was drawn from, or None (built exactly as the files say).
        models: with several interfaces, each one's model as built, in the scene's order (``model`` is the
            first's); empty for one.
    """

    world: object
    model: RigModel
    truth_seed: int | None
    models: tuple = ()

    def true_lights(self) -> list:
        """(3,) per point light of the scene, where it really stands (world frame, m)."""
        return [lt.position for lt in self.world.lights]

    def ground_truth(self, *, spp: int, world=None, use_cache: bool = True,
                     progress: Callable[[str], None] | None = None, warn: Callable[[str], None] | None = None):
        """The path-traced ground truth of the world (or of ``world``, e.g. one frame of a sequence), two
        independent renders of the union, the real and the synthetic objects (:mod:`lftransfer.sim.ground_truth`)."""
        from lftransfer.sim.ground_truth import render_ground_truth

        return render_ground_truth(self.world if world is None else world, spp=spp, use_cache=use_cache,
                                   progress=progress, warn=warn)

    def quiet_ground_truth(self, judge, *, spp: int, world=None, multiple: int = 1, use_cache: bool = True,
                           parts: int = 1, render=None, progress: Callable[[str], None] | None = None,
                           warn: Callable[[str], None] | None = None, budget_s: float | None = None):
        """The ground truth of the world (or of ``world``, one frame of a sequence) rendered in rounds until its
        noise on the cross term is at most a third of the error ``judge`` measures, each later round in ``parts``
        renders through ``render``, the later rounds within ``budget_s`` seconds
        (:func:`lftransfer.sim.reference.quiet_ground_truth`): (ground truth, ``Reference``)."""
        from lftransfer.sim.reference import quiet_ground_truth

        return quiet_ground_truth(self.world if world is None else world, judge, spp=spp, multiple=multiple,
                                  use_cache=use_cache, parts=parts, render=render, progress=progress, warn=warn,
                                  budget_s=budget_s)

    def fidelity_floor(self, rig, result, gt, settings, *, time_s: float = 0.0, cross=None,
                       progress: Callable[[str], None] | None = None):
        """The fidelity floor of a run on the simulated rig ``rig`` (a list of one per interface where there are
        several; :func:`lftransfer.sim.floor.fidelity_floor`:
        both sides' floors and the run's error scored as they are), at ``time_s`` of an animated world; ``cross``:
        the frame's own cross term to score, where it is not ``result``'s.

        Raises:
            ValueError: ``rig`` is not the simulated rig (the floor renders with its truth).
        """
        from lftransfer.sim.floor import fidelity_floor
        from lftransfer.sim.rig import SimRig

        rigs = list(rig) if isinstance(rig, (list, tuple)) else [rig]
        if not all(isinstance(r, SimRig) for r in rigs):
            raise ValueError(f"the fidelity floor needs the simulated rig, got {type(rigs[0]).__name__}")
        return fidelity_floor(rig, self.world, result, gt, settings, time_s=time_s, cross=cross,
                              progress=progress)

    def probe_errors(self, probe, world_to_array) -> dict | None:
        """How well a light probe's measurement (:class:`~lftransfer.real_depth.probe.ProbeMeasurement`, in the
        frame ``world_to_array`` (4, 4) takes for the array's) shows the room as it is
        (:func:`lftransfer.sim.metrics.probe_errors`); None where the world has no room light."""
        from lftransfer.sim.metrics import probe_errors

        env = getattr(self.world, "environment", None)
        return None if env is None else probe_errors(probe, env.radiance_map(), world_to_array)

    def real_view_depth(self, *, time_s: float = 0.0, spp: int = 16):
        """(H, W) float32 the distance from the view camera's centre to the real objects as they stand at
        ``time_s``, along each pixel's ray (the mean over ``spp`` rays of those that hit), metres; inf where no real
        object is seen."""
        from lftransfer.sim.ground_truth import view_distances

        world = self.world.at(time_s)
        return view_distances(world.real, world.view, spp)

    def lightfield_depth(self, model: RigModel, U: int, V: int, *, time_s: float = 0.0):
        """(K, V, U) the real objects' true depth along each light field entry's centre ray of ``model`` (the
        pipeline's rig model), metres (NaN: off the data or nothing there): the measured depth's oracle
        (:func:`lftransfer.sim.ground_truth.lightfield_depths`)."""
        from lftransfer.sim.ground_truth import lightfield_depths

        return lightfield_depths(self.world, model, U, V, time_s=time_s)

    def score_cross(self, gt, cross):
        """A cross term ((H, W, 3) the composite minus the composite without the exchange) scored as the fidelity
        floor scores a run: (real side, synthetic side), noise-corrected (:func:`lftransfer.sim.floor.score_cross`)."""
        from lftransfer.sim.floor import score_cross

        return score_cross(gt, cross)

    def calibration_errors(self, calibration):
        """A calibration's errors against the rig as built
        (:class:`lftransfer.sim.calibration_errors.CalibrationErrors`; for several interfaces,
        :class:`~lftransfer.sim.calibration_errors.InterfacesCalibrationErrors`)."""
        from lftransfer.sim.calibration_errors import calibration_errors, interfaces_calibration_errors

        if self.models:
            return interfaces_calibration_errors(calibration, self.models, true_lights=self.true_lights())
        return calibration_errors(calibration, self.model, true_lights=self.true_lights())


def open_simulated_rig(scene, truth_seed: int | None, *, capture_spp: int = DEFAULT_CAPTURE_SPP):
    """The simulated rig of a scene and its oracle.

    Args:
        scene: the whole scene file (the rig takes its real objects as its hidden world).
        truth_seed: seed of the hidden truth (how the rig as built and the lights differ from the files), or None.
        capture_spp: rays per LF camera pixel.

    Returns:
        (``SimRig``, :class:`Oracle`).
    """
    from lftransfer.sim.rig import SimRig
    from lftransfer.sim.truth import hidden_world

    one_interface(scene)
    world, truth = hidden_world(scene, truth_seed)
    rig = SimRig(world, truth=truth, capture_spp=capture_spp, operator_seed=truth_seed)
    return rig, Oracle(world=world, model=rig.truth, truth_seed=truth_seed)


def one_interface(scene) -> None:
    """A :class:`~lftransfer.scenes.SceneError` for a scene of several light field interfaces, where one simulated
    rig is wanted (it would simulate the first interface alone); :func:`open_simulated_interfaces` opens them."""
    if scene.interfaces:
        from lftransfer.scenes import SceneError
        from lftransfer.scenes.interfaces import interfaces_named

        raise SceneError(f"{interfaces_named(scene)}: lft run, lft calibrate, lft render, lft live and lft twin take "
                         "them; this command simulates one (docs/interfaces.md)")


def open_simulated_interfaces(scene, truth_seed: int | None, *, capture_spp: int = DEFAULT_CAPTURE_SPP):
    """The simulated rigs of a scene with several interfaces, one per interface in one world
    (:class:`~lftransfer.sim.interfaces.SimInterfaces`), and their oracle.

    Returns:
        (list of ``SimRig``, :class:`Oracle` with every interface's true model in ``models``).
    """
    from lftransfer.sim.interfaces import SimInterfaces
    from lftransfer.sim.truth import hidden_world, true_interfaces

    world, _ = hidden_world(scene, truth_seed)
    joined = SimInterfaces(world, truths=true_interfaces(scene, truth_seed), capture_spp=capture_spp,
                           operator_seed=truth_seed)
    return joined.rigs, Oracle(world=world, model=joined.truths[0], truth_seed=truth_seed,
                               models=tuple(joined.truths))


def hidden_oracle(scene, truth_seed: int | None) -> Oracle:
    """The oracle of the hidden truth ``truth_seed`` draws for ``scene``, without a rig (a recording made on the
    simulated rig, the device twin's world)."""
    from lftransfer.rig.model import nominal_interfaces
    from lftransfer.sim.truth import hidden_world, true_interfaces

    world, truth = hidden_world(scene, truth_seed)
    models = tuple((true_interfaces(scene, truth_seed) or nominal_interfaces(scene)) if scene.interfaces else ())
    return Oracle(world=world, model=models[0] if models else truth if truth is not None else nominal_rig(scene.rig),
                  truth_seed=truth_seed, models=models)


def oracle_of_recording(scene, meta: dict) -> Oracle | None:
    """The oracle of a recording made on the simulated rig (its manifest names the truth seed), or None for a
    recording of a physical rig."""
    if meta.get("rig") != "sim" or "truth_seed" not in meta:
        return None
    return hidden_oracle(scene, meta["truth_seed"])
