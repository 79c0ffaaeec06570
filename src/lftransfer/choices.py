"""Every choice a run makes, with its values and its one default (docs/architecture.md, "Settings").

Each choice is a ``Literal`` type; its values are read off the type (``values(Renderer)``), so the scene model
(pydantic), the command line (typer), studies and :func:`lftransfer.settings.resolve_settings` share one
definition. Nothing else in the project writes a choice's default.

This module imports nothing of the project, so the scene format, the renderer and the faces can all use it.
"""

from __future__ import annotations

from typing import Literal, get_args

LightingModel = Literal["area", "point", "prefiltered"]
"""How the captured light field lights the synthetic scene: ``"area"`` (lenslet apertures sampled), ``"point"``
(the paper's projective point lights) or ``"prefiltered"`` (:mod:`lftransfer.render.lights`)."""

Reconstruction = Literal["box", "linear"]
"""Area model: how the captured light field is read between lenslet centres, ``"linear"`` (blended across the
three lenslets around each aperture point) or ``"box"`` (one sample per lenslet over its whole aperture)."""

Projection = Literal["box", "depth", "solve"]
"""Area model: what the projector is sent, ``"solve"`` (the light field solved so that the real surface, as the
rig measures it with one extra frame, receives the synthetic objects' irradiance;
:mod:`lftransfer.transfer.surface_solve`), ``"depth"`` (a light field prefiltered from the same measured depth;
:mod:`lftransfer.transfer.projection`) or ``"box"`` (each entry the mean of the synthetic light over its lenslet's
aperture)."""

Window = Literal["edge", "cut"]
"""Area model: what the synthetic scene receives from beyond the lenslets' window, ``"edge"`` (the captured light
field read at the window's edge) or ``"cut"`` (nothing)."""

Renderer = Literal["auto", "fast", "exact"]
"""The synthetic renderer: ``"auto"`` (the fast path where the synthetic scene allows it), ``"fast"``
(:mod:`lftransfer.render.fast`) or ``"exact"`` (path tracing, every lenslet summed at every ray)."""

RigModel = Literal["calibrated", "nominal", "oracle"]
"""What the pipeline knows of the rig: ``"calibrated"`` (calibrate through the rig first), ``"nominal"`` (the rig
file's values) or ``"oracle"`` (the simulated rig's hidden truth: a verification baseline)."""

Composite = Literal["over", "depth"]
"""How the view camera's final frame is put together: ``"over"`` (the synthetic render over the real view: real
objects never hide synthetic ones, the paper's composite) or ``"depth"`` (the nearer surface per pixel, from the
synthetic render's depth and the real scene's depth measured by the rig; :func:`lftransfer.composite.composite_depth`).
"""

DirectLight = Literal["point", "probe"]
"""What lights the synthetic objects directly: ``"point"`` (the virtual twins of the scene's point lights; on a
scene with a light probe, one point light at the probe map's brightest direction, the negative control) or
``"probe"`` (the environment the light probe's mirror ball shows, ``[light] kind = "probe"``)."""

LiveLoop = Literal["decoupled", "sync"]
"""The live loop: ``"decoupled"`` (captures on their own thread at the devices' rate, frames at the renderer's
rate with the newest capture) or ``"sync"`` (one capture inside every frame; :mod:`lftransfer.transfer.live`)."""

Simulator = Literal["process", "thread"]
"""Where the simulated rig renders its captures in a live loop: ``"process"`` (a child process of its own, at a
lower scheduling priority and with its own Dr.Jit threads, so that the renderer has the cores when it wants them;
:mod:`lftransfer.sim.process`) or ``"thread"`` (in the loop's own process, sharing the renderer's threads)."""

LIGHTING_MODELS: tuple[str, ...] = get_args(LightingModel)
RECONSTRUCTIONS: tuple[str, ...] = get_args(Reconstruction)
PROJECTIONS: tuple[str, ...] = get_args(Projection)
WINDOWS: tuple[str, ...] = get_args(Window)
RENDERERS: tuple[str, ...] = get_args(Renderer)
RIG_MODELS: tuple[str, ...] = get_args(RigModel)
LIVE_LOOPS: tuple[str, ...] = get_args(LiveLoop)
COMPOSITES: tuple[str, ...] = get_args(Composite)
DIRECT_LIGHTS: tuple[str, ...] = get_args(DirectLight)
SIMULATORS: tuple[str, ...] = get_args(Simulator)

DEFAULT_LIGHTING_MODEL: LightingModel = "area"
DEFAULT_RECONSTRUCTION: Reconstruction = "linear"
DEFAULT_PROJECTION: Projection = "solve"
DEFAULT_WINDOW: Window = "edge"
DEFAULT_RENDERER: Renderer = "auto"
DEFAULT_COMPOSITE: Composite = "over"
DEFAULT_RIG_MODEL: RigModel = "calibrated"
"""Runs calibrate by default; a study defaults to it too (its ``rig_model``)."""
DEFAULT_LIVE_LOOP: LiveLoop = "decoupled"
"""``lft live`` and ``lft bench --live`` run at the renderer's rate."""
DEFAULT_SEQUENCE_LOOP: LiveLoop = "sync"
"""A written sequence (``lft render --mode live``) is synchronous unless asked: its frames then depend on no
clock, so a rerun writes the same frames."""

DEFAULT_SIMULATOR: Simulator = "process"
"""The decoupled live loop on the simulated rig runs the simulator in a process of its own. A loop that waits for
each capture (the synchronous live loop, a run's bounce loop) renders nothing beside it and keeps it in process,
where it has every core."""
DEFAULT_SIMULATOR_THREADS = 1
"""Dr.Jit threads of the simulator's process: the page's frame rate before the captures' rate."""
DEFAULT_SIMULATOR_NICE = 7
"""How much lower the simulator process's scheduling priority is (``nice``, 0 to 19). Linux then gives the renderer
a core whenever it wants one and the simulator what the renderer leaves: the higher, the more of the page's frame
rate is kept and the fewer captures per second come (docs/performance.md, "The simulator beside the renderer";
measured in docs/results.md, "Where the simulator renders beside the decoupled loop")."""

DEFAULT_SIMULATOR_SHARE = 0.0
"""Side by side: the simulator process runs beside the frames at its lower priority, which keeps some 90 % of the
page's frame rate. A share above 0 makes them take turns instead (:class:`lftransfer.transfer.share.TurnTaking`):
the simulator stopped while a frame renders, then alone for its share of the time with all its threads. At the
paper's resolution that gives more captures per second for fewer frames (docs/performance.md, "The simulator
beside the renderer")."""

LENSLET_RECONSTRUCTION: Reconstruction = "box"
LENSLET_WINDOW: Window = "cut"
"""What one lenslet physically sends or records: one radiance per direction over its whole aperture, nothing beyond
its window. A bare :class:`~lftransfer.render.lights.LightFieldLight` (a projector's lenslets on the simulated rig,
a calibration's flat field) is lit this way; a run's synthetic side reads the captured light field with the run's
reconstruction and window instead (:data:`DEFAULT_RECONSTRUCTION`, :data:`DEFAULT_WINDOW`)."""

NON_AREA = {"reconstruction": LENSLET_RECONSTRUCTION, "projection": "box", "window": LENSLET_WINDOW}
"""What reconstruction, projection and window become when the lighting model is not the area model: those three
choices only exist for lenslets treated as the area lights they are."""

COMPARED_LIGHTING_MODELS: tuple[str, ...] = ("area", "point")
"""The lighting models a run compares when it compares every choice (``lft demo``, ``lft run --compare-models``):
the prefiltered model is a speed-up of the point model, not a third answer."""

DEFAULT_BOUNCES = 2
"""N, light field exchanges after the direct frame."""
MAX_BOUNCES = 20
"""The most bounces any run, sequence or study accepts. Each adds one exchange; the energy of bounce n falls
roughly as the product of both sides' albedo and form factor, 1e-2 per bounce on Fig. 4. (The live page runs up
to :data:`lftransfer.app.viewer.session.MAX_EXCHANGES` exchanges per shown frame.)"""

DEFAULT_MAX_DEPTH = 3
"""Surface interactions per path inside a half-space (``[render] max_depth``): direct light and two
interreflections."""
DEFAULT_ANGULAR_SAMPLES = 48
DEFAULT_APERTURE_SAMPLES = 4
DEFAULT_SPP = 4
DEFAULT_GT_SPP = 2048
DEFAULT_CAPTURE_SPP = 4
"""Rays per LF camera pixel in the simulated rig."""
DEFAULT_PROJECTOR_FILL = 0.95

DEFAULT_BLAS_THREADS = 1
"""Threads of the BLAS libraries (NumPy's, SciPy's and OpenCV's OpenBLAS) in a process that renders with Dr.Jit.
OpenBLAS's threads keep spinning for a while after each matrix product and take the cores from Dr.Jit's kernels
that follow (docs/performance.md, "BLAS threads beside Dr.Jit"); one thread costs the products little, since the
project's products are small. ``LFT_BLAS_THREADS`` or ``lft --blas-threads`` change it; 0 leaves the libraries'
own default (:func:`lftransfer.backend.bound_blas`)."""


def values(choice) -> tuple[str, ...]:
    """The values of a choice's ``Literal`` type, in their documented order."""
    return get_args(choice)


def check_choice(name: str, value, choice) -> None:
    """Raise ValueError naming ``name`` when ``value`` is not one of ``choice``'s values (None passes: it means
    "the scene's")."""
    if value is not None and value not in get_args(choice):
        raise ValueError(f"{name}: expected one of {', '.join(get_args(choice))}, got {value!r}")
