"""The bounce loop of light field transfer (docs/architecture.md, "The bounce loop").

Light transport is linear, so the real scene's response to a projected light field is separated from its
response to the real point light by differencing two captures, and each bounce can be inspected alone:

- direct: R_0 = decode(capture(black)); Ls_0, S_0 rendered with the virtual point light only (with
  ``projection = "depth"`` or ``"solve"`` one more capture, the projector white, first gives the real scene's
  depth, from which every Ls_n is prefiltered, :mod:`lftransfer.transfer.projection`, or its projector image
  solved, :mod:`lftransfer.transfer.surface_solve`);
- bounce n >= 1: R_n = (decode(capture(encode(g_n Ls_{n-1}))) - R_0) / g_n, the gain g_n filling the
  projector's range; Ls_n, S_n rendered with the synthetic scene lit by R_{n-1} only;
- final frame: real view = view camera while the projector shows encode(Ls_0 + ... + Ls_{N-1});
  synthetic view = S_0 + ... + S_N.
"""

from __future__ import annotations

from contextlib import nullcontext
from dataclasses import dataclass, field
from typing import Callable, NamedTuple

import numpy as np

from lftransfer import choices
from lftransfer.backend import bound_blas
from lftransfer.real_depth.probe import ProbeMeasurement
from lftransfer.composite import composite, composite_depth
from lftransfer.lightfield import LightField
from lftransfer.real_depth import ViewDepth, fuse_depths, measure_structured_light
from lftransfer.real_depth.outline import lightfield_view_depths, photograph_clean_plate
from lftransfer.render.base import ViewImage
from lftransfer.rig.base import Rig
from lftransfer.rig.model import RigModel
from lftransfer.rig.requests import RealScene
from lftransfer.scenes import SyntheticScene
from lftransfer.transfer.projection import measure_depth
from lftransfer.transfer.synthetic_side import SyntheticSide
from lftransfer.transfer.timer import StageTimer

Progress = Callable[[str], None]


@dataclass(frozen=True)
class TransferSettings:
    """How a transfer runs. Its defaults are :mod:`lftransfer.choices`'; a run builds it from its scene with
    :func:`lftransfer.settings.resolve_settings`.

    Attributes:
        bounces: N, light field exchanges after the direct frame.
        angular_samples: U = V of the light field grid.
        lighting_model: how the captured light field lights the synthetic scene ("area", "point", "prefiltered").
        aperture_samples: lenslet aperture points per shading point (area model).
        reconstruction: how the captured light field is read between lenslet centres when it lights the
            synthetic scene: "box" or "linear" (area model; :mod:`lftransfer.render.lights`).
        projection: what the projector is sent: "box" (each entry the mean of the synthetic light over its
            lenslet's aperture), "depth" (prefiltered from the real scene's depth measured through the rig with
            one extra frame; area model; :mod:`lftransfer.transfer.projection`) or "solve" (the projector's drive
            solved against the surface that depth measures; :mod:`lftransfer.transfer.surface_solve`).
        window: what the synthetic scene receives from beyond the lenslets' window: "edge" (the captured light
            field read at the window's edge) or "cut" (nothing; area model; :mod:`lftransfer.render.lights`).
        composite: how the final frame is put together: "over" (the synthetic render over the real view) or
            "depth" (the nearer surface per pixel: the real scene's depth, measured through the rig as the depth
            projection measures it, carried into the view camera; :mod:`lftransfer.real_depth`).
        direct_light: what lights the synthetic objects directly: "point" (the point lights' virtual twins; on a
            light probe scene one point light at the probe's brightest direction) or "probe" (the environment the
            light probe shows; :mod:`lftransfer.real_depth.probe`).
        lf_spp: rays per light field sample when rendering the outgoing light field.
        view_spp: rays per view pixel for synthetic renders.
        projector_fill: fraction of the projector's full radiance that the brightest sample of g_n Ls is given.
        bounce_views: also capture the real view for every bounce (for the Fig. 4 panel).
        renderer: "exact" (path tracing, every lenslet summed at every ray) or "fast" (irradiance cached at the
            vertices of a fine tessellation, :mod:`lftransfer.render.fast`), as resolved for the scene
            (:func:`~lftransfer.render.selection.resolve_renderer`); settings made by hand may say "auto" (the
            synthetic side resolves it by the same rule).
        max_depth: surface interactions per path inside the synthetic half-space (the scene's
            ``render.max_depth``; 1 = direct light only).
        seed: Monte Carlo seed of the synthetic renders.
    """

    bounces: int = choices.DEFAULT_BOUNCES
    angular_samples: int = choices.DEFAULT_ANGULAR_SAMPLES
    lighting_model: choices.LightingModel = choices.DEFAULT_LIGHTING_MODEL
    aperture_samples: int = choices.DEFAULT_APERTURE_SAMPLES
    reconstruction: choices.Reconstruction = choices.DEFAULT_RECONSTRUCTION
    projection: choices.Projection = choices.DEFAULT_PROJECTION
    window: choices.Window = choices.DEFAULT_WINDOW
    composite: choices.Composite = choices.DEFAULT_COMPOSITE
    direct_light: choices.DirectLight = "point"
    lf_spp: int = choices.DEFAULT_SPP
    view_spp: int = choices.DEFAULT_SPP
    projector_fill: float = choices.DEFAULT_PROJECTOR_FILL
    bounce_views: bool = True
    renderer: choices.Renderer = choices.DEFAULT_RENDERER
    max_depth: int = choices.DEFAULT_MAX_DEPTH
    seed: int = 0

    def __post_init__(self) -> None:
        # final as built: under any lighting model but the area model, reconstruction, projection and window are
        # the lenslets' own (choices.NON_AREA), whoever builds the settings
        if self.lighting_model != "area":
            for name, value in choices.NON_AREA.items():
                object.__setattr__(self, name, value)

    @property
    def measures_depth(self) -> bool:
        """Whether a transfer measures the real scene's depth: for the projection prefilter or the depth
        composite."""
        return self.prefilters or self.composite == "depth"

    @property
    def prefilters(self) -> bool:
        """Whether the projection is made from a measured depth (``projection`` ``"depth"``, the prefilter, or
        ``"solve"``, the solve against the measured surface; both need the area model, and something to project: at
        least one bounce)."""
        return self.projection in ("depth", "solve") and self.bounces > 0       # NON_AREA made it "box" elsewhere


@dataclass
class Bounce:
    """One bounce's images and light fields.

    Attributes:
        index: n (0 = direct light).
        real_lf: R_n, light field captured from the real scene due to this bounce (K, V, U, 3).
        synthetic_lf: Ls_n, light field the synthetic scene sends back, or None where not needed.
        synthetic_view: S_n, view render of the synthetic scene due to this bounce.
        real_view: the real scene's view image due to this bounce (differenced), when captured.
        projector_gain: g_n used to capture R_n (None for n = 0).
    """

    index: int
    real_lf: LightField
    synthetic_lf: LightField | None
    synthetic_view: ViewImage
    real_view: np.ndarray | None = None
    projector_gain: float | None = None

    @property
    def real_energy(self) -> float:
        """Radiant flux of R_n through the array, W (mean over RGB)."""
        return float(np.mean(self.real_lf.power()))

    @property
    def synthetic_energy(self) -> float:
        """Radiant flux of Ls_n through the array, W (mean over RGB); 0 when Ls_n was not rendered."""
        return 0.0 if self.synthetic_lf is None else float(np.mean(self.synthetic_lf.power()))


@dataclass
class TransferResult:
    """Everything a transfer produced.

    Attributes:
        bounces: direct light and each bounce, index 0..N.
        real_view: final real view, (H, W, 3) float32, projector showing encode(sum of Ls_0..Ls_{N-1}); for
            N = 0 the direct view (projector black).
        real_view_direct: real view with the projector black (for the 0-bounce composite).
        synthetic_view: sum of S_0..S_N (rgb) with the coverage alpha of S_0.
        projected_image: the final projector image (device integers; black for N = 0).
        projected_lf: sum of Ls_0..Ls_{N-1} (:func:`final_projection`; all zero for N = 0).
        clipped_fraction: fraction of lit light field samples above the projector's range in the final frame.
        captured_raw: the LF camera image of the direct frame (device integers).
        saturated_fraction: fraction of the direct frame's LF camera codes at full scale (light clipped there
            is lost to the synthetic side).
        timings_s: seconds per stage.
        depth: (K, V, U) the real scene's depth the projection prefilter or the depth composite used (measured,
            or given to :func:`run_transfer`), metres (NaN where none was found), or None (neither needs one).
        view_depth: the real scene's depth in the view camera (``composite == "depth"``), else None.
        depth_sources: the depths it was made of (the LF camera's carried into the view as it is; inside the
            real objects' measured outline, for a view camera on the real side; structured light's where
            measured), for the report; empty with the over composite.
        probe: the light probe's measurement on a scene lit by one (photographed here or given), else None.
        interfaces: with several interfaces (:func:`lftransfer.transfer.interfaces.run_interfaces`), each one's
            bounces (its R_n and Ls_n; None for an interface switched off), in the scene's order; :attr:`bounces` is
            the first exchanging one's. Empty for one interface.
        projected_images: with several interfaces, each exchanging one's final projector image, in the scene's
            order (:attr:`projected_image` is the first's). Empty for one interface.
        captured_raws: with several interfaces, each exchanging one's LF camera image of the direct frame (device
            integers), in the scene's order (:attr:`captured_raw` is the first's). Empty for one interface.
    """

    bounces: list[Bounce]
    real_view: np.ndarray
    real_view_direct: np.ndarray
    synthetic_view: ViewImage
    projected_image: np.ndarray
    projected_lf: LightField
    clipped_fraction: float
    captured_raw: np.ndarray
    saturated_fraction: float = 0.0
    timings_s: dict[str, float] = field(default_factory=dict)
    depth: np.ndarray | None = None
    view_depth: ViewDepth | None = None
    depth_sources: tuple[ViewDepth, ...] = ()
    probe: ProbeMeasurement | None = None
    interfaces: tuple = ()
    projected_images: tuple = ()
    captured_raws: tuple = ()

    def composite(self) -> np.ndarray:
        """(H, W, 3) the final frame: the synthetic render and the real view, by the run's composite (the over
        operator, or the nearer surface where :attr:`view_depth` is given)."""
        return composite_view(self.synthetic_view, self.real_view, self.view_depth)

    def composite_direct(self) -> np.ndarray:
        """(H, W, 3) the frame without any exchange (bounce 0 on both sides), composited alike."""
        s0 = self.bounces[0].synthetic_view
        return composite_view(ViewImage(rgb=s0.rgb, alpha=self.synthetic_view.alpha, depth=self.synthetic_view.depth),
                              self.real_view_direct, self.view_depth)


def composite_view(synthetic: ViewImage, real_view: np.ndarray, view_depth: ViewDepth | None) -> np.ndarray:
    """The synthetic render ``synthetic`` and the real view: the over operator
    (:func:`~lftransfer.composite.composite`), or, with the real scene's depth in the view camera, the depth-aware
    composite (:func:`~lftransfer.composite.composite_depth`)."""
    if view_depth is None:
        return composite(synthetic.rgb, synthetic.alpha, real_view)
    return composite_depth(synthetic.rgb, synthetic.alpha, synthetic.depth, real_view, view_depth.depth,
                           view_depth.sigma)


def projector_gain(lf: LightField, max_radiance: float, fill: float = 0.95) -> float:
    """Gain g that brings the brightest sample of ``lf`` to ``fill`` of the projector's full radiance."""
    peak = float(np.max(lf.data))
    return fill * max_radiance / peak if peak > 0 else 1.0


def real_response(rig: Rig, decoder, encoder, incident: LightField, direct: LightField, gain: float, *,
                  timer: Callable | None = None) -> LightField:
    """The real scene's response to a light field, separated by differencing.

    R = (decode(capture(encode(g * incident))) - direct) / g, where ``direct`` is the decoded capture with the
    projector black. The gain g puts a weak light field into the projector's range and is divided out again.

    Args:
        rig: the rig (project, capture_lf), in the real scene.
        decoder: raw LF camera image -> LightField.
        encoder: LightField -> projector image.
        incident: light field to project (K, V, U, 3).
        direct: R_0, decoded capture with the projector black.
        gain: g > 0.
        timer: optional stage timer (a context manager factory taking a stage name).

    Returns:
        LightField of the real scene's response (K, V, U, 3).
    """
    if not gain > 0:
        raise ValueError(f"projector gain must be > 0, got {gain}")
    time_it = timer or (lambda _stage: nullcontext())
    with time_it("encode"):
        pattern = encoder(incident * gain)
    rig.project(pattern)
    with time_it("capture"):
        raw = rig.capture_lf().codes
    with time_it("decode"):
        return (decoder(raw) - direct) / gain


def final_projection(bounces: list[Bounce]) -> LightField:
    """What the projector shows in the final frame: Ls_0 + ... + Ls_{N-1} for bounces 0..N, radiance
    (K, V, U, 3) float32.

    The last bounce's Ls_N would only light the real side for a bounce N + 1 that is not run, so it is left out;
    for N = 0 the sum is empty (an all-zero light field): nothing from the synthetic side reaches the real one.
    """
    first = bounces[0].synthetic_lf
    total = LightField.zeros(first.array, first.data.shape[2], first.data.shape[1])
    for b in bounces[:-1]:
        total = total + b.synthetic_lf
    return total


def count_steps(settings: TransferSettings) -> int:
    """Number of progress callbacks :func:`run_transfer` makes (for progress bars)."""
    per_bounce = 3 + (1 if settings.bounce_views else 0)
    return 4 + 2 * int(settings.measures_depth) + settings.bounces * per_bounce + 2


def run_transfer(rig: Rig, model: RigModel, scene: SyntheticScene, settings: TransferSettings = TransferSettings(), *,
                 progress: Progress | None = None, time_s: float = 0.0,
                 depth: np.ndarray | None = None, view_depth: ViewDepth | None = None,
                 probe: ProbeMeasurement | None = None) -> TransferResult:
    """Run N bounces of light field transfer between the rig's real scene and the synthetic scene.

    Args:
        rig: the rig (only its :class:`~lftransfer.rig.base.Rig` methods are used).
        model: what the pipeline knows of the rig (nominal or calibrated), never the rig's hidden truth.
        scene: the synthetic part of the scene (:class:`~lftransfer.scenes.SyntheticScene`): its ``synthetic``
            objects, ``light`` and ``view`` (in world coordinates; moved into the array's frame by
            ``model.world_to_array()``).
        settings: see :class:`TransferSettings`.
        progress: called with a short description at the start of each step.
        time_s: the moment of an animated scene: the synthetic objects and (through
            :class:`~lftransfer.rig.requests.RealScene`) the simulated rig's real objects are posed there.
        depth: (K, V, U) the real scene's depth for the projection prefilter, metres (NaN: unknown), measured
            earlier (a live sequence's, so that a check of its frames prefilters and composites as the frames did);
            None: measured here with one extra frame, and, for the depth composite, the view camera's depth by
            structured light too (:func:`~lftransfer.real_depth.measure_structured_light`, 24 extra photographs),
            the better of the two per pixel.
        view_depth: with ``depth``, the real scene's depth in the view camera measured with it (another run's on
            the same rig and model, :attr:`TransferResult.view_depth`), for the depth composite; None: carried
            from ``depth`` here.
        probe: on a scene lit by a light probe, its measurement made earlier (another run's on the same rig);
            None: the probe is photographed here (:meth:`SyntheticSide.measure_probe`).

    Returns:
        TransferResult with every bounce kept.
    """
    step = progress or (lambda _msg: None)
    bound_blas()        # NumPy's products beside Dr.Jit's kernels: lftransfer.backend
    timer = StageTimer()
    side = SyntheticSide(model, scene, settings, time_s=time_s)
    decoder, encoder = side.decoder, side.encoder
    black = rig.info.black()
    if scene.probe is not None:
        if probe is None:
            step("photograph the light probe (the mirror ball)")
            with timer("probe"):
                probe = side.measure_probe(rig)
        side.set_probe(probe.radiance)

    # Direct light.
    step("capture direct (projector black)")
    rig.setup(RealScene(time_s=time_s))
    rig.project(black)
    with timer("capture"):
        raw0 = rig.capture_lf().codes
    step("capture view, projector black")
    with timer("capture_view"):
        real_view_direct = rig.capture_view().radiance
    with timer("decode"):
        r0 = decoder(raw0)
    measured = _real_depth(rig, model, scene, settings, side, r0, depth, time_s, step, timer)
    depth = measured.depth
    step("render synthetic direct")
    ls0, s0 = side.render(side.direct_lights, settings.seed, timer)
    bounces = [Bounce(0, r0, ls0, s0, real_view=real_view_direct)]
    step("direct done")

    for n in range(1, settings.bounces + 1):
        bounces.append(_bounce(n, bounces[n - 1], rig, model, settings, side, r0, real_view_direct, step, timer))

    # Final frame: the projector shows Ls_0 + ... + Ls_{N-1}, an empty sum for N = 0.
    step("final frame: project the sum of the synthetic light fields")
    projected = final_projection(bounces)
    pattern, real_view, clipped = _final_frame(rig, model, settings, encoder, projected, real_view_direct, timer)
    step("final frame captured")
    rgb = sum(b.synthetic_view.rgb for b in bounces)
    synthetic_view = ViewImage(rgb=rgb.astype(np.float32), alpha=s0.alpha, depth=s0.depth)
    view_depth, sources = _view_depth(model, scene, settings, measured, view_depth, real_view_direct, timer)
    return TransferResult(bounces=bounces, real_view=real_view, real_view_direct=real_view_direct,
                          synthetic_view=synthetic_view, projected_image=pattern, projected_lf=projected,
                          clipped_fraction=clipped, captured_raw=raw0,
                          saturated_fraction=float(np.mean(raw0 >= 2 ** rig.info.lf_camera_bits - 1)),
                          timings_s=timer.totals, depth=depth, view_depth=view_depth,
                          depth_sources=sources, probe=probe)


class _Measured(NamedTuple):
    """What :func:`_real_depth` measured of the real scene (each None where not measured)."""

    depth: np.ndarray | None             # (K, V, U) metres along the array's normal
    structured: ViewDepth | None         # the view camera's depth by structured light
    response: LightField | None          # the light field under the projector's white light alone
    plate: np.ndarray | None             # (H, W, 3) the view camera's clean plate, projector black


def _real_depth(rig: Rig, model: RigModel, scene: SyntheticScene, settings: TransferSettings, side: SyntheticSide,
                r0: LightField, depth: np.ndarray | None, time_s: float, step: Progress,
                timer: StageTimer) -> _Measured:
    """The real scene's depth where the transfer needs it (the projection from a measured depth, the depth
    composite): ``depth`` as given, else measured with one extra frame (projector white); for the depth composite
    without a given depth also the view camera's by structured light and its clean plate (the real objects taken
    away for one photograph, then posed again at ``time_s``). The synthetic side projects from the depth."""
    structured = plate = response = None
    if not settings.measures_depth:
        return _Measured(None, None, None, None)   # nothing needs it: the result carries no depth
    if depth is None and settings.composite == "depth":
        step("measure the real scene's depth in the view camera (structured light; the clean plate)")
        with timer("structured_light"):
            structured = measure_structured_light(rig, model, scene.view, side.encoder, settings.angular_samples)
        with timer("clean_plate"):
            plate = photograph_clean_plate(rig, time_s)
    else:
        step("the real scene's depth in the view camera: from the LF camera alone")
    if depth is None:
        step("measure the real scene's depth (projector white)")
        with timer("measure_depth"):
            swept = measure_depth(rig, side.decoder, side.encoder, model.projector.max_radiance,
                                  settings.angular_samples, settings.angular_samples, r0)
            depth, response = swept.depth, swept.response
    if settings.prefilters:
        side.set_depth(depth)
    return _Measured(depth, structured, response, plate)


def _bounce(n: int, prev: Bounce, rig: Rig, model: RigModel, settings: TransferSettings, side: SyntheticSide,
            r0: LightField, real_view_direct: np.ndarray, step: Progress, timer: StageTimer) -> Bounce:
    """Bounce n: the real side answers g Ls_{n-1} projected (R_n, and its view where asked for); the synthetic side
    is lit by R_{n-1} only (Ls_n, S_n)."""
    gain = projector_gain(prev.synthetic_lf, model.projector.max_radiance, settings.projector_fill)
    step(f"bounce {n}: project Ls_{n - 1} (gain {gain:.3g}), capture the real response")
    rn = real_response(rig, side.decoder, side.encoder, prev.synthetic_lf, r0, gain, timer=timer)
    real_view_n = None
    if settings.bounce_views:
        step(f"bounce {n}: capture real view")
        with timer("capture_view"):
            real_view_n = (rig.capture_view().radiance - real_view_direct) / gain
    step(f"bounce {n}: render synthetic lit by R_{n - 1}")
    with timer("incident_light"):
        incident = side.incident_light(prev.real_lf, settings.seed + n)
    lsn, sn = side.render([incident], settings.seed + 1000 * n, timer)
    bounce = Bounce(n, rn, lsn, sn, real_view=real_view_n, projector_gain=gain)
    step(f"bounce {n} done")
    return bounce


def _final_frame(rig: Rig, model: RigModel, settings: TransferSettings, encoder, projected: LightField,
                 real_view_direct: np.ndarray, timer: StageTimer) -> tuple[np.ndarray, np.ndarray, float]:
    """The final frame's projector image, real view and the share of projected light beyond the projector's
    range. With no bounce nothing crosses to the real side: the direct frame, projector black."""
    black = rig.info.black()
    if settings.bounces == 0:
        return black, real_view_direct, 0.0
    with timer("encode"):
        pattern = encoder(projected)
    lit = projected.data[projected.data > 0]
    clipped = float(np.mean(lit > model.projector.max_radiance)) if lit.size else 0.0
    rig.project(pattern)
    with timer("capture_view"):
        real_view = rig.capture_view().radiance
    rig.project(black)
    return pattern, real_view, clipped


def _view_depth(model: RigModel, scene: SyntheticScene, settings: TransferSettings, measured: _Measured,
                given: ViewDepth | None, photograph: np.ndarray, timer: StageTimer):
    """The real scene's depth in the view camera for the depth composite and what it was made of: the one given,
    else the LF camera's carried into the view (for a view camera on the real side, inside the real objects'
    outline measured through the rig: :func:`~lftransfer.real_depth.outline.lightfield_view_depths`), fused with
    structured light's where measured; (None, ()) for the over composite. The sources are the LF camera's
    depth carried into the view as it is, the outline's where made (which the fusion takes instead of it), then
    structured light's."""
    if settings.composite != "depth":
        return None, ()
    if given is not None:
        return given, (given,)
    with timer("view_depth"):
        sources = lightfield_view_depths(measured.depth, measured.response, model, scene.view, photograph,
                                         measured.plate)
        used = sources[-1]
        if measured.structured is None:
            return used, sources
        return fuse_depths(used, measured.structured), (*sources, measured.structured)

