"""The synthetic half of a transfer: the rig model's codecs, the synthetic scene posed in the array's frame, its
renderer, the virtual point light and the view camera, set up once and shared by the bounce loop and the live
loop.
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from lftransfer.lightfield import LightField
from lftransfer.lightfield.window import SteepRays, steep_rays
from lftransfer.optics.geometry import rigid_points, rigid_vectors
from lftransfer.render.base import ViewImage
from lftransfer.render.camera import sensor_dict
from lftransfer.render.lights import EDGE_REACH, EmitterLight, EnvironmentLight, LightFieldLight, PointLight
from lftransfer.render.selection import make_renderer, resolve_renderer
from lftransfer.rig.model import RigModel
from lftransfer.scenes import SyntheticScene, check_synthetic
from lftransfer.scenes.frame import scene_in_frame
from lftransfer.real_depth.surface import measured_surface
from lftransfer.transfer.projection import DepthPrefilter
from lftransfer.transfer.surface_solve import SolvingEncoder, SurfaceSolve, TargetedLightField

__all__ = ["SyntheticSide", "render_sides"]


class SyntheticSide:
    """Everything the pipeline renders and encodes, for one rig model and one synthetic scene.

    The renderer works in the lens array's frame (interface plane z = 0): the scene (objects, point light, view
    camera) is moved there by ``model.world_to_array()``; a moving scene is posed at a time first
    (:meth:`pose`), so the frame change is exact.

    Args:
        model: what the pipeline knows of the rig (nominal or calibrated).
        scene: the synthetic part of the scene (:class:`~lftransfer.scenes.SyntheticScene`).
        settings: a ``TransferSettings`` (angular samples, lighting model, reconstruction, samples, renderer).
        time_s: the moment of an animated scene the objects start at.
        primary: for one interface of several (docs/architecture.md, "Several interfaces"), the first interface's
            side, whose renderer, frame, lights and view camera this one shares: it decodes, lights and encodes
            through its own array, which stands in that frame at :attr:`array_pose`; the first poses and edits the
            shared scene. None: a side of its own (:meth:`through` makes the sides of several interfaces).

    Attributes:
        decoder: raw LF camera image -> LightField (K, V, U, 3).
        encoder: LightField -> projector image (:class:`~lftransfer.transfer.surface_solve.SolvingEncoder`: a
            light field carrying a surface target is solved against the measured surface, any other encoded as the
            rig model's encoder does).
        point_lights: the virtual twins of the real point lights (array frame), one per light of the scene.
        direct_lights: the synthetic scene's own light: the point lights, the light probe's map where one is set
            (:meth:`set_probe`), and its emitting objects where it has any
            (:class:`~lftransfer.render.lights.EmitterLight`).
        probe: the light probe's map (h, w, 3), array frame, or None.
        prefilter: the projection prefilter from the real scene's measured depth (:meth:`set_depth`), or None.
        surface_solve: the projection's solve against the measured real surface (:meth:`set_depth`,
            ``projection = "solve"``), or None. With neither, the box light field is projected.
        depth: the real scene's depth the projection uses, (K, V, U) metres, or None.
        array_pose: (4, 4) this side's array frame -> the renderer's frame, or None where they are the same (one
            interface, or the first of several).
    """

    def __init__(self, model: RigModel, scene: SyntheticScene, settings, *, time_s: float = 0.0,
                 primary: "SyntheticSide | None" = None, windows=None) -> None:
        from lftransfer.backend import mitsuba

        mi = mitsuba()
        self.model = model
        self._primary = primary
        self._frame = model.world_to_array() if primary is None else primary._frame     # world -> renderer
        self.array_pose = None if primary is None else self._frame @ np.linalg.inv(model.world_to_array())
        self.settings = settings
        self.scene = check_synthetic(scene)
        U = V = settings.angular_samples
        self.decoder = model.decoder(U, V)
        # every projection is measured against a frame with the projector black: light added to its black level
        self.encoder = SolvingEncoder(model.encoder(U, V, above_black=True))
        self.time_s = float(time_s)
        self.probe: np.ndarray | None = None
        posed = self._posed(self.time_s)
        if primary is None:
            self.renderer = self._renderer(posed, settings, windows)
            self._set_lights(posed)
            view = posed.view
            self.width, self.height = view.resolution
            self.sensor = mi.load_dict(sensor_dict(view.origin, view.target, view.up, view.fov_deg, self.width,
                                                   self.height))
        else:
            self.renderer, self.sensor = primary.renderer, primary.sensor
            self.width, self.height = primary.width, primary.height
            self.point_lights, self.direct_lights = primary.point_lights, primary.direct_lights
        self.prefilter: DepthPrefilter | None = None
        self.depth: np.ndarray | None = None
        self._steep: tuple[np.ndarray | None, SteepRays] | None = None        # (the depth, its steep rays)
        self._gain: tuple | None = None   # (the probe's map, the depth, the solve, (the entries' factor, the points'))

    @classmethod
    def through(cls, models: Sequence[RigModel], scene: SyntheticScene, settings, *,
                time_s: float = 0.0) -> list["SyntheticSide"]:
        """The synthetic side of each of several interfaces (``models``, in the scene's order): one renderer in the
        first one's frame, in which paths between synthetic objects are cut where they cross an array
        (:mod:`~lftransfer.render.windows`); one light field lit, and one sent, through each array. One model: a
        list of one ordinary side."""
        from lftransfer.render.windows import Windows

        if len(models) == 1:
            return [cls(models[0], scene, settings, time_s=time_s)]
        if scene.probe is not None:
            raise ValueError("a light probe scene has one interface: the probe's window is one array's "
                             f"(the scene gives {len(models)} [[interface]] tables)")
        frame = models[0].world_to_array()
        windows = Windows.of([m.array for m in models], [frame @ np.linalg.inv(m.world_to_array()) for m in models])
        first = cls(models[0], scene, settings, time_s=time_s, windows=windows)
        return [first, *(cls(m, scene, settings, time_s=time_s, primary=first) for m in models[1:])]

    @property
    def surface_solve(self) -> SurfaceSolve | None:
        """The projection's solve against the measured surface (the encoder's), or None."""
        return self.encoder.solve

    def posed(self) -> SyntheticScene:
        """The synthetic scene at the current time, in the lens array's frame."""
        return self._posed(self.time_s)

    def measure_probe(self, rig):
        """Photograph the scene's light probe through ``rig`` and recover the room's light
        (:func:`~lftransfer.real_depth.probe.photograph_probe`, the ball and view camera as this side knows them);
        returns the :class:`~lftransfer.real_depth.probe.ProbeMeasurement`. The scene must have a probe."""
        from lftransfer.real_depth.probe import MirrorBall, photograph_probe

        if self.scene.probe is None:
            raise ValueError("measure_probe: the scene has no light probe ([light] kind = 'probe')")
        posed = self.posed()
        p = posed.probe
        ball = MirrorBall(tuple(p.ball_centre), p.ball_radius, tuple(p.ball_reflectance))
        return photograph_probe(rig, self.scene.probe.ball_centre, ball, posed.view, self.model.array.extent(),
                                width=p.map_width)

    @staticmethod
    def _renderer(posed: SyntheticScene, settings, windows=None):
        """The renderer the settings name (``settings.renderer`` as resolved; "auto" in settings made by hand is
        resolved here by the same rule, :func:`~lftransfer.render.selection.resolve_renderer`)."""
        return make_renderer(posed.synthetic, resolve_renderer(posed, settings.renderer), settings.max_depth,
                             windows)

    def _posed(self, t: float) -> SyntheticScene:
        return scene_in_frame(self.scene.at(t), self._frame)

    def pose(self, t: float) -> bool:
        """Move the synthetic objects to their pose at time ``t`` (seconds); returns whether any moved."""
        t = float(t)
        if self._primary is not None:      # the first interface's side moves the shared renderer
            self.time_s = t
            return False
        if t == self.time_s or not self.scene.moving:
            self.time_s = t
            return False
        self.time_s = t
        return self.renderer.update(self._posed(t).synthetic)

    def set_scene(self, scene: SyntheticScene, settings=None) -> None:
        """Replace the synthetic scene (objects moved, materials or lights changed, as an interactive edit does)
        and optionally the settings; the codecs stay, the renderer is updated in place where it can be. With several
        interfaces, the first's side is changed first, then the others (:func:`render_sides`)."""
        scene = check_synthetic(scene)
        settings = settings if settings is not None else self.settings
        self.scene, self.settings = scene, settings
        if self._primary is not None:      # the first interface's side, changed first, holds the shared part
            first = self._primary
            self.renderer, self.point_lights, self.direct_lights = first.renderer, first.point_lights, \
                first.direct_lights
            if self.depth is not None:
                self.set_depth(self.depth)
            return
        posed = self._posed(self.time_s)
        kind = resolve_renderer(posed, settings.renderer)
        if (kind, settings.max_depth, len(posed.synthetic)) == (self.renderer.kind, self.renderer.max_depth,
                                                               len(self.renderer.objects)):
            self.renderer.update(posed.synthetic)
        else:
            self.renderer = make_renderer(posed.synthetic, kind, settings.max_depth, self.renderer.windows)
        self._set_lights(posed)
        if self.depth is not None:
            self.set_depth(self.depth)

    def set_depth(self, depth: np.ndarray | None) -> None:
        """Make every outgoing projection from this depth of the real scene, when the settings ask for it
        (``settings.prefilters``): the prefiltered light field (``projection = "depth"``,
        :mod:`~lftransfer.transfer.projection`) or the solve against the surface the depth measures (``"solve"``,
        :mod:`~lftransfer.transfer.surface_solve`); None: the box light field. The steep light read beyond the
        lenslets' window is checked against it (:mod:`~lftransfer.lightfield.window`).

        Args:
            depth: (K, V, U) depth of each light field entry's centre ray, metres (NaN: unknown), from
                :func:`~lftransfer.transfer.projection.measure_depth`.
        """
        s = self.settings
        if depth is None or not s.prefilters:
            self.prefilter, self.depth, self.encoder.solve = None, None, None
            return
        U = s.angular_samples
        if s.projection == "solve":
            self.prefilter = None
            solve = self.encoder.solve
            if solve is None or self.depth is not depth or solve.seed != s.seed:
                self.encoder.solve = SurfaceSolve(measured_surface(depth, self.model.array, U, U), self.encoder.encoder,
                                                  seed=s.seed)
            self.depth = depth
            return
        self.encoder.solve = None
        self.depth = depth
        old = self.prefilter
        if old is not None and old.depth is depth and old.spp == s.lf_spp and old.seed == s.seed:
            return
        self.prefilter = DepthPrefilter(np.asarray(depth), self.model.array, U, U, spp=s.lf_spp, seed=s.seed)

    def set_probe(self, radiance: np.ndarray | None) -> None:
        """Light the synthetic objects by the light probe's map ((h, w, 3) radiance in the lens array's frame,
        :class:`~lftransfer.real_depth.probe.ProbeMeasurement`), as the settings' ``direct_light`` says: the map
        itself (``"probe"``; the array blocks the directions its lenslets record, whose light arrives through it as
        the captured light field, and lenslet cameras see the map behind the objects) or one point light at its
        brightest direction (``"point"``, :func:`probe_point_light`)."""
        self.probe = None if radiance is None else np.asarray(radiance, np.float32)
        self._set_lights(self._posed(self.time_s))

    def _set_lights(self, posed: SyntheticScene) -> None:
        self.point_lights = [PointLight(np.asarray(lt.position, float), np.asarray(lt.intensity, float))
                             for lt in posed.lights]
        probe = []
        if self.probe is not None and self.settings.direct_light == "probe":
            array = self.model.array
            probe = [EnvironmentLight(self.probe, blocker=array.extent(), window=array.half_width,
                                      samples=PROBE_SAMPLES, seed=self.settings.seed)]
        elif self.probe is not None:
            probe = [probe_point_light(self.probe, posed)]
        self.direct_lights = [*self.point_lights, *probe] \
            + ([EmitterLight(seed=self.settings.seed, windows=self.renderer.windows)] if posed.emitters else [])

    def incident_light(self, real_lf: LightField, seed: int, aperture_samples: int | None = None) -> LightFieldLight:
        """The captured real light field as a light of the synthetic half-space (the settings' lighting model
        reconstruction and window; the steep light checked against the measured depth where there is one).
        ``aperture_samples``: the area model's aperture points per shading point, None: the settings' (a denser
        reference, the bench's exact path, asks for more)."""
        s = self.settings
        samples = s.aperture_samples if aperture_samples is None or s.lighting_model != "area" else aperture_samples
        return LightFieldLight(real_lf, side="synthetic", model=s.lighting_model, aperture_samples=int(samples),
                               seed=seed, reconstruction=s.reconstruction, window=s.window,
                               steep=self.steep_rays(real_lf), pose=self.array_pose)

    def steep_rays(self, real_lf: LightField) -> SteepRays | None:
        """Which samples beyond the lenslets' window the synthetic side reads from their edge
        (:func:`~lftransfer.lightfield.window.steep_rays`), checked against the measured depth where there is one;
        found once per depth (a live loop builds a light per frame). None without an edge window."""
        s = self.settings
        if s.lighting_model != "area" or s.window != "edge":
            return None
        depth = self.depth
        if self._steep is None or self._steep[0] is not depth or self._steep[1].shape != real_lf.data.shape[:3]:
            self._steep = (depth, steep_rays(real_lf, EDGE_REACH, depth))
        return self._steep[1]

    def render(self, lights: Sequence, seed: int, timer: Callable | None = None) -> tuple[LightField, ViewImage]:
        """Ls (the light field the synthetic scene sends through the array; prefiltered where :attr:`prefilter` is
        set, carrying its measured surface's target where :attr:`surface_solve` is) and S (its view image) under
        ``lights``; ``timer(stage)`` is an optional context manager factory timing "render_lightfield", "prefilter",
        "surface_target", "steep_room" and "render_view". Under a visible light probe's map (the direct frame of a
        light probe scene) with a measured depth (the prefilter's or the solve's), the room behind the synthetic
        objects is sent stronger for the steep room light the array's panel shades on the real side
        (:mod:`~lftransfer.transfer.room`; under the solve, its part of the measured points' targets too)."""
        from contextlib import nullcontext

        time_it = timer or (lambda _stage: nullcontext())
        ls = self._lightfield(lights, seed, time_it)
        room = [light for light in lights if isinstance(light, EnvironmentLight) and light.visible]
        if room and self.depth is not None:
            with time_it("steep_room"):
                # the room behind the synthetic objects, sent stronger for the steep light the panel shades
                # (transfer/room.py): only the entries whose landing point was measured change; under the solve,
                # the measured points' targets too
                behind = self._lightfield([room[0].seen_only()], seed, lambda _stage: nullcontext())
                entries, points = self._room_gain(ls)
                ls.data += (entries[..., None] - 1.0) * behind.data
                if isinstance(ls, TargetedLightField) and isinstance(behind, TargetedLightField):
                    ls.target = ls.target + (points[:, None] - 1.0) * behind.target
        with time_it("render_view"):
            s = self.settings
            # the view is composited over the real one, which shows the room: the render shows the objects only
            seen = [light.hidden() if isinstance(light, EnvironmentLight) else light for light in lights]
            view = self.renderer.render_view(self.sensor, self.width, self.height, seen, spp=s.view_spp, seed=seed)
        return ls, view

    def lightfield(self, lights: Sequence, seed: int, timer: Callable | None = None) -> LightField:
        """Ls alone (:meth:`render` without the view): another interface's outgoing light field, whose view the
        first interface's side renders."""
        from contextlib import nullcontext

        return self._lightfield(lights, seed, timer or (lambda _stage: nullcontext()))

    def _lightfield(self, lights: Sequence, seed: int, time_it) -> LightField:
        """The light field the synthetic scene sends through the array under ``lights``: prefiltered where
        :attr:`prefilter` is set; the box light field carrying the measured surface's target where
        :attr:`surface_solve` is (:class:`~lftransfer.transfer.surface_solve.TargetedLightField`)."""
        s = self.settings
        U = V = s.angular_samples
        pf, solve = self.prefilter, self.encoder.solve
        if pf is not None:
            with time_it("render_lightfield"):
                # one "sample" per ray: every primary ray still goes through render_samples
                radiance = self.renderer.render_samples(*self._placed(pf.origins, pf.directions), lights, 1,
                                                        seed=seed).radiance
            with time_it("prefilter"):
                return pf.apply(radiance)
        with time_it("render_lightfield"):
            lf = self.renderer.render_lightfield(self.model.array, lights, U, V,
                                                 model="area" if s.lighting_model == "area" else "point",
                                                 spp=s.lf_spp, seed=seed, pose=self.array_pose)
        if solve is None:
            return lf
        with time_it("surface_target"):
            # the synthetic objects' irradiance at the measured surface, through the lenslets' apertures
            if not solve.rays:                   # nothing measured that a lenslet lights: no rays to trace
                return TargetedLightField(lf.data, lf.array, np.zeros((solve.points, 3), np.float32))
            radiance = self.renderer.render_samples(*self._placed(solve.origins, solve.directions), lights, 1,
                                                    seed=seed).radiance
            return TargetedLightField(lf.data, lf.array, solve.target(radiance))

    def _placed(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) rays of this side's array frame in the renderer's frame (themselves where they are the same),
        kept for the arrays last given (the prefilter's and the solve's rays stay while the depth does)."""
        if self.array_pose is None:
            return origins, directions
        kept = getattr(self, "_placed_rays", None)
        if kept is None or kept[0] is not origins or kept[1] is not directions:
            moved = (rigid_points(self.array_pose, origins).astype(np.float32),
                     rigid_vectors(self.array_pose, directions).astype(np.float32))
            for a in moved:
                a.flags.writeable = False        # constant rays: the renderer keeps their Dr.Jit copies
            self._placed_rays = kept = (origins, directions, moved)
        return kept[2]

    def _room_gain(self, ls: LightField) -> tuple[np.ndarray, np.ndarray | None]:
        """The steep room light's factors for the light probe's map and the measured depth
        (:mod:`~lftransfer.transfer.room`), found once per map and depth: (K, V, U) per light field entry, and (N,)
        per point of the solve's measured surface (None without the solve)."""
        from lftransfer.transfer.room import landing_points, room_gain_at

        depth, solve = self.depth, self.encoder.solve
        if self._gain is None or self._gain[0] is not self.probe or self._gain[1] is not depth \
                or self._gain[2] is not solve:
            # one lookup table for both: the entries' landing points, then the solve's measured points
            landed = landing_points(self.model.array, depth, ls.u, ls.v).reshape(-1, 3)
            where = landed if solve is None else np.concatenate([landed, solve.surface.points])
            gain = room_gain_at(self.probe, self.model.array, where)
            entries = gain[:len(landed)].reshape(np.shape(depth))
            self._gain = (self.probe, depth, solve, (entries, None if solve is None else gain[len(landed):]))
        return self._gain[3]


def render_sides(sides: Sequence[SyntheticSide], lights: Sequence, seed: int, timer: Callable | None = None, *,
                 used: Sequence[int] | None = None) -> tuple[dict[int, LightField], ViewImage]:
    """The outgoing light field of each of several interfaces' sides (:meth:`SyntheticSide.through`) under one set
    of ``lights``, and the synthetic view: the first side renders the view and its own light field together, each
    other its light field alone (seeds ``seed + 17 i``).

    Args:
        sides: every interface's side, in the scene's order.
        lights: the synthetic scene's lights (its own and every interface's captured light field).
        seed: the first side's Monte Carlo seed.
        timer: :meth:`SyntheticSide.render`'s stage timer.
        used: the interfaces whose light field is wanted; None: all.

    Returns:
        ({interface: Ls}, S).
    """
    ls0, view = sides[0].render(lights, seed, timer)
    wanted = range(len(sides)) if used is None else used
    out = {0: ls0} if 0 in wanted else {}
    for i in wanted:
        if i:
            out[i] = sides[i].lightfield(lights, seed + 17 * i, timer)
    return out, view


PROBE_SAMPLES = 16          # directions of the light probe's map per shading point
PROBE_POINT_DISTANCE_M = 1.0    # the negative control's point light: this far from the synthetic objects' centre


def probe_point_light(radiance: np.ndarray, posed: SyntheticScene) -> PointLight:
    """The light probe's map as one point light (the negative control, ``direct_light = "point"``): at the map's
    brightest direction, :data:`PROBE_POINT_DISTANCE_M` from the centre of the synthetic objects' boxes, with the
    intensity that gives a surface facing it there the irradiance the whole map gives it (W m^-2 times the
    distance squared). ``radiance``: (h, w, 3) in the lens array's frame; ``posed``: the scene in that frame."""
    from lftransfer.real_depth.probe import EnvironmentMap

    full = EnvironmentMap(np.asarray(radiance, np.float32), np.ones(np.shape(radiance)[:2], bool))
    d = full.brightest_direction()
    boxes = [o.bounds() for o in posed.synthetic] or [(np.zeros(3), np.zeros(3))]
    centre = np.mean([(np.asarray(lo) + np.asarray(hi)) / 2 for lo, hi in boxes], axis=0)
    irradiance = EnvironmentLight(radiance).irradiance_towards(d)
    return PointLight(centre + PROBE_POINT_DISTANCE_M * d, irradiance * PROBE_POINT_DISTANCE_M ** 2)
