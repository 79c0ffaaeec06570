"""One resolution of the settings a run uses: a scene plus what its caller overrides -> :class:`RunSettings`.

A choice's values and its default live in :mod:`lftransfer.choices`; the scene file may set them (``[render]``,
``[rig] angular_samples``); a caller (the command line, a study's setting, the live page, the bench) may
override them (:class:`Overrides`; None: the scene's; each field also declares its command-line option).
:func:`resolve_settings` applies the two in that order, once, into final values: the rule that only the area model
has a reconstruction, projection and window (:data:`lftransfer.choices.NON_AREA`), the renderer the scene gets
("fast" or "exact") and its ``max_depth``. A run, its progress total, its comparison re-runs, a sequence, the live
loop and its page, the bench, studies and the cluster's workers all take its result, so a setting reported is the
setting used.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

from lftransfer import choices
from lftransfer.render.selection import resolve_renderer
from lftransfer.transfer.bounce import TransferSettings

__all__ = ["COMPARABLE", "Overrides", "RunSettings", "SimulatorSettings", "resolve_settings"]

COMPARABLE = ("lighting_model", "reconstruction", "projection", "window")
"""The choices a run may measure beside its own (``compare``): each alternative is the same run with that one
setting changed."""

_AREA_ONLY = ("reconstruction", "projection", "window")


def _setting(help: str, *, choice=None, command_default=None, flag: str | None = None, **bounds) -> Any:  # noqa: A002
    """A field of :class:`Overrides` (None: the scene's) with what its command-line option shows: ``help``, the
    choice's ``Literal`` type (its values), the value the commands start from (``command_default``; None: the
    scene's), the option's name where it is not the field's (``flag``) and bounds (``min``, ``max``,
    ``metavar``). :func:`lftransfer.app.cli.options.setting_options` makes the options from these, so the setting,
    its option and docs/cli.md say the same."""
    return field(default=None, metadata={"help": help, "choice": choice, "command_default": command_default,
                                         "flag": flag, "bounds": bounds})


@dataclass(frozen=True)
class Overrides:
    """What a caller asks for beyond the scene file; None (or an empty tuple) leaves the scene's choice.

    Each field but ``compare`` is a setting a command may take as an option (``--bounces``, ``--lighting-model``,
    ...; its help is the field's ``metadata["help"]``).

    Attributes:
        bounces: N, light field exchanges after the direct frame (0 .. :data:`lftransfer.choices.MAX_BOUNCES`).
        lighting_model, reconstruction, projection, window, renderer, composite, direct_light: one value of the
            choice's ``Literal`` (:mod:`lftransfer.choices`).
        gt_spp: samples per pixel of each ground-truth render (>= 1).
        quiet_reference: render the ground truth in rounds until its noise on the cross term is at most a third
            of the error (:mod:`lftransfer.sim.reference`; ``gt_spp`` is then the first round's).
        reference_budget_s: seconds the quiet reference's later rounds may take (None: as long as the run took
            before them).
        simulator, simulator_threads, simulator_nice, simulator_share, renderer_threads: where a live loop's
            simulated rig renders its captures, the threads each side gets and how they take turns
            (:class:`SimulatorSettings`).
        compare: per choice of :data:`COMPARABLE`, further values measured beside the run's own (full re-runs;
            reconstruction, projection and window only under the area model), e.g.
            ``{"lighting_model": ("area", "point")}``.
    """

    bounces: int | None = _setting(
        f"Number of bounces, light field exchanges after the direct frame (0 to {choices.MAX_BOUNCES}).",
        command_default=choices.DEFAULT_BOUNCES, min=0, max=choices.MAX_BOUNCES, metavar="N")
    lighting_model: choices.LightingModel | None = _setting(
        f"How the captured light field lights the synthetic objects (default: the scene's render.lighting_model, "
        f"{choices.DEFAULT_LIGHTING_MODEL} unless the scene says).", choice=choices.LightingModel)
    reconstruction: choices.Reconstruction | None = _setting(
        f"Area model: how the captured light field is read between lenslets (default: the scene's, "
        f"{choices.DEFAULT_RECONSTRUCTION} unless the scene says).", choice=choices.Reconstruction)
    projection: choices.Projection | None = _setting(
        f"Area model: what the projector is sent: the box light field, the light field prefiltered from the real "
        f"scene's depth measured through the rig, or the light field solved against the surface that depth "
        f"measures (default: the scene's, {choices.DEFAULT_PROJECTION} unless the scene says).",
        choice=choices.Projection)
    window: choices.Window | None = _setting(
        f"Area model: what the synthetic objects receive from beyond the lenslets' window: the captured light "
        f"field read at the window's edge, or nothing (default: the scene's, {choices.DEFAULT_WINDOW} unless the "
        f"scene says).", choice=choices.Window)
    renderer: choices.Renderer | None = _setting(
        "Synthetic renderer: auto (the fast path where the scene allows it) | fast | exact (path tracing); the "
        "report names the one used.", choice=choices.Renderer, command_default=choices.DEFAULT_RENDERER)
    composite: choices.Composite | None = _setting(
        f"How the final frame is put together: the synthetic render over the real view, or the nearer surface per "
        f"pixel (the real scene's depth measured through the rig, carried into the view camera; default: the "
        f"scene's, {choices.DEFAULT_COMPOSITE} unless the scene says).", choice=choices.Composite)
    direct_light: choices.DirectLight | None = _setting(
        "What lights the synthetic objects directly: the scene's point lights, or the environment its light probe "
        "shows; on a light probe scene, point is one point light at the probe's brightest direction, for "
        "comparison (default: probe where the scene's [light] has kind = 'probe', else point).",
        choice=choices.DirectLight)
    gt_spp: int | None = _setting(
        f"Ground-truth samples per pixel (>= 1; default: the scene's render.gt_spp, {choices.DEFAULT_GT_SPP} "
        f"unless the scene says).", min=1, metavar="N")
    quiet_reference: bool | None = _setting(
        "Render the ground truth in rounds (the objects' pixels only after the first) until its noise on the "
        "cross term is at most a third of the error, within --reference-budget; --gt-spp is the first round's "
        "samples.")
    reference_budget_s: float | None = _setting(
        "Seconds the quiet reference's later rounds may take, all together (default: as long as the run took "
        "before them, so a judged run takes at most twice as long; raise it where the run says the target was not "
        "met).", flag="--reference-budget", min=1.0, metavar="SECONDS")
    simulator: choices.Simulator | None = _setting(
        f"Live loops on the simulated rig: where it renders its captures, in a process of its own at a lower "
        f"priority (the renderer keeps the cores it wants) or in a thread of this process (sharing the renderer's "
        f"threads; default: {choices.DEFAULT_SIMULATOR}).", choice=choices.Simulator)
    simulator_threads: int | None = _setting(
        f"Dr.Jit threads of the simulator's process (default: {choices.DEFAULT_SIMULATOR_THREADS}).",
        min=1, metavar="N")
    simulator_nice: int | None = _setting(
        f"How much lower the simulator process's priority is, 0 to 19: higher keeps more of the page's frame rate, "
        f"lower gives more captures per second (default: {choices.DEFAULT_SIMULATOR_NICE}).",
        min=0, max=19, metavar="N")
    simulator_share: float | None = _setting(
        f"The simulator process's share of the time while frames render one after another: stopped while a frame "
        f"renders, it runs alone for its share before the next; 0: side by side at its lower priority (default: "
        f"{choices.DEFAULT_SIMULATOR_SHARE}).", min=0.0, max=0.9, metavar="FRACTION")
    renderer_threads: int | None = _setting(
        "Dr.Jit threads of the renderer's process in a live loop (default: one per core).", min=1, metavar="N")
    compare: tuple[tuple[str, tuple[str, ...]], ...] = ()

    def __post_init__(self) -> None:
        problems = []
        if self.bounces is not None and not (isinstance(self.bounces, int) and
                                             0 <= self.bounces <= choices.MAX_BOUNCES):
            problems.append(f"bounces: expected an integer from 0 to {choices.MAX_BOUNCES}, got {self.bounces!r}")
        if self.reference_budget_s is not None and not (isinstance(self.reference_budget_s, (int, float))
                                                        and self.reference_budget_s >= 1):
            problems.append(f"reference_budget_s: expected a number of seconds >= 1, got {self.reference_budget_s!r}")
        if self.gt_spp is not None and not (isinstance(self.gt_spp, int) and self.gt_spp >= 1):
            problems.append(f"gt_spp: expected an integer >= 1 (or None: the scene's), got {self.gt_spp!r}")
        for name, kind in (("simulator_threads", int), ("simulator_nice", int), ("renderer_threads", int),
                           ("simulator_share", float)):
            value, bounds = getattr(self, name), self.__dataclass_fields__[name].metadata["bounds"]
            low, high = bounds["min"], bounds.get("max")            # the option's bounds: defined once, above
            if value is not None and not (isinstance(value, (int, kind)) and not isinstance(value, bool)
                                          and value >= low and (high is None or value <= high)):
                what = "an integer" if kind is int else "a fraction"
                problems.append(f"{name}: expected {what} from {low:g}" + (f" to {high:g}" if high else " up")
                                + f" (or None: the default), got {value!r}")
        kinds = {"lighting_model": choices.LightingModel, "reconstruction": choices.Reconstruction,
                 "projection": choices.Projection, "window": choices.Window, "renderer": choices.Renderer,
                 "composite": choices.Composite, "direct_light": choices.DirectLight, "simulator": choices.Simulator}
        for name, kind in kinds.items():
            try:
                choices.check_choice(name, getattr(self, name), kind)
            except ValueError as exc:
                problems.append(str(exc))
        compare = dict(self.compare)
        for name, alternatives in compare.items():
            if name not in COMPARABLE:
                problems.append(f"compare: expected a choice among {', '.join(COMPARABLE)}, got {name!r}")
                continue
            for value in alternatives:
                try:
                    choices.check_choice(f"compare {name}", value, kinds[name])
                except ValueError as exc:
                    problems.append(str(exc))
        if problems:
            raise ValueError("; ".join(problems))

    @classmethod
    def comparing_all(cls, **overrides) -> "Overrides":
        """Overrides that also measure every other value of every comparable choice (``lft demo``,
        ``lft run --compare-models``)."""
        kinds = {"lighting_model": choices.COMPARED_LIGHTING_MODELS, "reconstruction": choices.RECONSTRUCTIONS,
                 "projection": choices.PROJECTIONS, "window": choices.WINDOWS}
        return cls(**overrides, compare=tuple(kinds.items()))


@dataclass(frozen=True)
class SimulatorSettings:
    """Where a live loop's simulated rig renders its captures, and the threads each side gets (resolved once by
    :func:`resolve_settings`; :func:`lftransfer.runs.rigs.open_rig` opens the rig with it).

    Attributes:
        where: "process" (:class:`lftransfer.sim.process.SimulatorProcess`) or "thread" (in the loop's process;
            :data:`lftransfer.choices.Simulator`).
        threads: Dr.Jit threads of the simulator's process (with "process").
        nice: how much lower its scheduling priority is (with "process"), 0 to 19.
        share: with "process", the simulator's share of the time while frames render one after another, taken in
            turns with them (:class:`lftransfer.transfer.share.TurnTaking`); 0: side by side, at its priority only.
        renderer_threads: Dr.Jit threads of the loop's own process (None: Dr.Jit's default, one per core).
    """

    where: choices.Simulator = "thread"
    threads: int = choices.DEFAULT_SIMULATOR_THREADS
    nice: int = choices.DEFAULT_SIMULATOR_NICE
    share: float = choices.DEFAULT_SIMULATOR_SHARE
    renderer_threads: int | None = None

    def to_json(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class RunSettings:
    """The settings a run uses, resolved once (:func:`resolve_settings`).

    Attributes:
        transfer: the transfer's settings (bounces, lighting model, reconstruction, projection, window, renderer,
            angular samples, aperture samples, rays per light field entry and per view pixel).
        gt_spp: samples per pixel of each ground-truth render (with ``quiet_reference``, of its first round).
        quiet_reference: render the ground truth until it is quiet enough (:mod:`lftransfer.sim.reference`).
        reference_budget_s: the seconds its later rounds may take (None: as long as the run took before them).
        comparisons: the re-runs measured beside the run: (choice, value) pairs, each the run with that one choice
            changed, in the order of :data:`COMPARABLE`; none that equals the run's own value, and no
            reconstruction, projection or window unless the area model.
        reruns: the transfer settings of each comparison, resolved as a run asking for that value would be
            (:meth:`rerun`).
        adjustments: what the resolution changed from what the scene and the overrides asked for, and why, one
            sentence each (a live loop's projection where the real objects move, a decoupled loop's simulator in
            this process with several light field interfaces).
        simulator: where a live loop's simulated rig renders its captures and the threads each side gets (the live
            loops open their rig with it: ``lft live``, ``lft render --mode live``, ``lft bench --live``): by
            default its own process beside the decoupled loop, this process where the loop waits for each capture.
    """

    transfer: TransferSettings
    gt_spp: int
    comparisons: tuple[tuple[str, str], ...] = ()
    reruns: tuple[TransferSettings, ...] = ()
    quiet_reference: bool = False
    adjustments: tuple[str, ...] = ()
    reference_budget_s: float | None = None
    simulator: SimulatorSettings = SimulatorSettings()

    @property
    def bounces(self) -> int:
        return self.transfer.bounces

    def rerun(self, name: str, value: str) -> TransferSettings:
        """The transfer settings of the comparison re-run that sets ``name`` to ``value`` (no bounce views): the
        settings :func:`resolve_settings` gives with that override (another lighting model brings its own
        reconstruction, projection and window)."""
        return self.reruns[self.comparisons.index((name, value))]

    def to_json(self) -> dict:
        """The settings as JSON (the run's report and a sequence's key write them)."""
        # quiet_reference only where asked for: a sequence's key of the same settings stays as it was
        return {"transfer": asdict(self.transfer), "gt_spp": self.gt_spp,
                **({"quiet_reference": True} if self.quiet_reference else {}),
                **({"reference_budget_s": self.reference_budget_s}
                   if self.quiet_reference and self.reference_budget_s is not None else {}),
                "comparisons": [list(c) for c in self.comparisons]}


def resolve_settings(scene, overrides: Overrides = Overrides(), *, live: bool = False,
                     loop: choices.LiveLoop | None = None, **transfer_changes) -> RunSettings:
    """The settings a run on ``scene`` uses with ``overrides``.

    In order: :mod:`lftransfer.choices`' defaults (through the scene model's defaults), the scene file's
    ``[render]`` and ``[rig] angular_samples`` (``render.lf_spp`` rays per light field entry, else
    ``render.spp``), then ``overrides``; under any lighting model but the area model, reconstruction, projection
    and window become :data:`lftransfer.choices.NON_AREA`. In a live loop (``live``) the real scene's depth is
    measured once, so where the scene's real objects move a projection made from it ("depth", "solve") becomes
    the box light field, and :attr:`RunSettings.adjustments` says so.

    Args:
        scene: ``SceneConfig`` (or its synthetic part).
        overrides: what the caller asks for (:class:`Overrides`).
        live: the settings of a live loop (a live sequence), which measures the real scene's depth once.
        loop: the live loop they are for ("decoupled" or "sync"; None: no live loop), which sets where the simulated
            rig renders by default (:class:`SimulatorSettings`).
        transfer_changes: further :class:`~lftransfer.transfer.bounce.TransferSettings` fields that are not
            choices (``bounce_views``, ``seed``, ``lf_spp``, ...), applied last.

    Returns:
        :class:`RunSettings`.
    """
    render = scene.render
    values = dict(bounces=choices.DEFAULT_BOUNCES, angular_samples=scene.rig.angular_samples,
                  lighting_model=render.lighting_model, aperture_samples=render.aperture_samples,
                  reconstruction=render.reconstruction, projection=render.projection, window=render.window,
                  lf_spp=render.lf_spp or render.spp, view_spp=render.spp, renderer=choices.DEFAULT_RENDERER,
                  max_depth=render.max_depth,
                  composite=render.composite, direct_light="probe" if scene.probe is not None else "point")
    for name in ("bounces", "lighting_model", "reconstruction", "projection", "window", "renderer", "composite",
                 "direct_light"):
        if getattr(overrides, name) is not None:
            values[name] = getattr(overrides, name)
    if values["direct_light"] == "probe" and scene.probe is None:
        raise ValueError("direct_light 'probe': the scene has no light probe (a [light] table with kind = 'probe')")
    area = values["lighting_model"] == "area"
    if not area:
        values.update(choices.NON_AREA)
    values.update(transfer_changes)
    values["renderer"] = resolve_renderer(scene, values["renderer"])
    transfer = TransferSettings(**values)
    adjustments = []
    if live and transfer.prefilters and any(o.moves for o in getattr(scene, "real", ())):
        adjustments.append(f"projection: the box light field, not the {transfer.projection} projection the scene "
                           "asks for: the real objects move, and the live loop measures the depth once")
        transfer = replace(transfer, projection="box")
    several = bool(getattr(scene, "interfaces", ()))
    if loop == "decoupled" and several and overrides.simulator is None:
        adjustments.append("simulator: in this process beside the decoupled loop, not in a process of its own, "
                           "which serves one light field interface")
    comparisons = []
    asked = dict(overrides.compare)
    for name in COMPARABLE:
        if name in _AREA_ONLY and not area:
            continue
        for value in asked.get(name, ()):
            if value != getattr(transfer, name) and (name, value) not in comparisons:
                comparisons.append((name, value))
    reruns = tuple(resolve_settings(scene, replace(overrides, **{name: value}, compare=()),
                                    **{**transfer_changes, "bounce_views": False}).transfer
                   for name, value in comparisons)
    gt_spp = overrides.gt_spp if overrides.gt_spp is not None else render.gt_spp
    return RunSettings(transfer=transfer, gt_spp=gt_spp, comparisons=tuple(comparisons), reruns=reruns,
                       quiet_reference=bool(overrides.quiet_reference), adjustments=tuple(adjustments),
                       reference_budget_s=overrides.reference_budget_s,
                       simulator=_simulator(overrides, loop, several))


def _simulator(overrides: Overrides, loop: str | None, several: bool = False) -> SimulatorSettings:
    """The simulator's place and threads as the overrides ask, else the defaults: its own process beside a
    decoupled loop of one light field interface, this process where the loop waits for each capture (a synchronous
    loop, a run) or the scene has several interfaces (``several``)."""
    where = overrides.simulator or (choices.DEFAULT_SIMULATOR if loop == "decoupled" and not several else "thread")
    threads = overrides.simulator_threads or choices.DEFAULT_SIMULATOR_THREADS
    nice = choices.DEFAULT_SIMULATOR_NICE if overrides.simulator_nice is None else overrides.simulator_nice
    share = choices.DEFAULT_SIMULATOR_SHARE if overrides.simulator_share is None else float(overrides.simulator_share)
    return SimulatorSettings(where=where, threads=threads, nice=nice, share=share,
                             renderer_threads=overrides.renderer_threads)
