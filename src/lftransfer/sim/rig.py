"""``SimRig``: a digital twin of the light field transfer rig.

It owns a hidden truth (the real objects and their materials, the point light, the true lens array and device
models, noise) and renders the real world physically with Mitsuba:

- the projector's lenslets are direction-dependent area lights (their aperture is the lattice cell), all
  summed at every shading point, with shadow rays (:class:`lftransfer.render.lights.LightFieldLight`);
- each LF camera pixel averages the radiance arriving along its ray direction over its lenslet's aperture;
- real-to-real interreflections come from path tracing inside the real half-space;
- the lens array is a black absorber just behind the interface plane;
- the LF camera adds shot and read noise, applies its response and quantises to its bit depth.

Calibration set-ups (:mod:`lftransfer.rig.requests`) are simulated too: a collimator (one spot per lenslet), a white
diffuser, a diffuser at the lenslets' focal plane, and a board held by an operator where the request says, off
by a hidden hand error (:class:`OperatorError`, drawn from the operator seed, never from the rig's truth).

The Monte Carlo sampling of the real world uses the same seed for every capture, like a deterministic physical
process: its error then cancels when captures are differenced; sensor noise does not.
"""

from __future__ import annotations

import numpy as np

from dataclasses import dataclass

from scipy.spatial.transform import Rotation

from lftransfer.choices import DEFAULT_CAPTURE_SPP
from lftransfer.optics.geometry import apply_homography, rectangle_to_world
from lftransfer.render.camera import sensor_dict
from lftransfer.render.lights import EnvironmentLight, LightFieldLight, PointLight
from lftransfer.render.base import aperture_offsets
from lftransfer.render.renderer import HalfSpaceRenderer
from lftransfer.render.shapes import board_shapes, lens_array_absorber
from lftransfer.rig.model import RigModel, nominal_interfaces
from lftransfer.rig.requests import (SCREEN_TRANSMISSION, Board, CleanPlate, Collimator, FocalPlaneDiffuser,
                                     LFCapture, LFFrame, MirrorBall, RealScene, RigInfo, Setup, ViewCapture, ViewFrame,
                                     WhiteField)
from lftransfer.scenes.frame import scene_in_frame

NOISE_SEED_STEP = 1009   # interface i's sensor noise and renders are seeded with the rig's seed + i * this
ROOM_SAMPLES = 16      # directions of the room's light per shading point (importance-sampled, shadow rays)
BALL_SPP = 64          # samples per pixel of the view camera's photograph of the mirror ball


@dataclass(frozen=True)
class OperatorError:
    """Sizes of the hidden errors of actions done by hand (drawn per action from the truth seed).

    Attributes:
        board_offset_m: a board's centre lands off the requested place by up to this much per axis.
        board_tilt_deg: ... and turned about a random axis by about this angle (standard deviation per axis
            of the rotation vector: ``board_tilt_deg / sqrt(3)``, so the angle's RMS is this).
    """

    board_offset_m: float = 0.003
    board_tilt_deg: float = 1.0


class SimRig:
    """Simulated rig for a scene (``lftransfer.scenes.SceneConfig``): implements :class:`lftransfer.rig.Rig`.

    Args:
        scene: the scene; its ``real`` objects become the hidden real world.
        truth: true rig model; defaults to the rig file's nominal values.
        capture_spp: rays per LF camera pixel (points on the lenslet aperture).
        view_spp: rays per view camera pixel.
        projector_samples: angular resolution (per axis) at which each projector lenslet's emission is
            resampled from the projector image.
        aperture_samples: points per projector lenslet aperture for each shading point.
        seed: seed of the hidden truth's noise.
        operator_seed: seed of the operator's hand errors (default: ``seed``).
        operator: sizes of the operator's hand errors (:class:`OperatorError`; ``OperatorError(0, 0)``: exact).
        interface: which of the scene's light field interfaces this rig's devices are (``[[interface]]`` index; 0
            for a ``[rig]`` scene). A scene of several is simulated by one rig per interface, joined
            (:class:`~lftransfer.sim.interfaces.SimInterfaces`): each sees the others' arrays and projectors.

    Example:
        >>> rig = SimRig(load_scene(builtin_scene("fig4")))       # doctest: +SKIP
        >>> rig.capture_lf().codes.shape                            # (1536, 2048, 3) uint16
    """

    def __init__(self, scene, *, truth: RigModel | None = None, capture_spp: int = DEFAULT_CAPTURE_SPP, view_spp: int = 4,
                 projector_samples: int = 64, aperture_samples: int = 2, seed: int | None = None,
                 operator_seed: int | None = None, operator: OperatorError = OperatorError(),
                 interface: int = 0) -> None:
        from lftransfer.backend import mitsuba

        mi = mitsuba()
        faces = scene.interfaces
        if not 0 <= interface < max(1, len(faces)):
            raise ValueError(f"SimRig: interface {interface} of a scene with {max(1, len(faces))} interface(s)")
        self.interface = int(interface)
        self._truth = truth or nominal_interfaces(scene)[self.interface]
        self._world_to_array = self._truth.world_to_array()
        # set-ups are placed in the rig's own frame: its interface's, as the scene places it (the world's for one)
        placement = np.asarray(self._truth.placement, np.float64) if self._truth.placement else np.eye(4)
        self._rig_to_array = self._world_to_array @ placement
        # The real world seen from the true lens array's own frame (interface plane z = 0); a moving scene is
        # posed at the time each RealScene request names (scene_in_frame of the posed world scene, exact).
        self._world_scene = scene
        self._time_s = 0.0
        scene = scene_in_frame(scene.at(0.0), self._world_to_array)
        self._scene = scene
        self._seed = int(scene.rig.seed if seed is None else seed) + NOISE_SEED_STEP * self.interface
        self._operator_seed = self._seed if operator_seed is None else int(operator_seed)
        self._operator = operator
        self._rng = np.random.default_rng(self._seed + 7)
        self.capture_spp = int(capture_spp)
        self.view_spp = int(view_spp)
        self.aperture_samples = int(aperture_samples)
        array = self._truth.array
        self._absorbers = {"lens_array_absorber": lens_array_absorber(array)}   # and the other interfaces' (join)
        self._siblings: list[SimRig] = []
        self._posed_siblings: dict = {}          # interface -> (its projector light, that light in this frame)
        self._real = HalfSpaceRenderer(scene.real, extra_shapes=self._absorbers, max_depth=scene.render.max_depth)
        self._point_lights = [PointLight(np.asarray(lt.position, float), np.asarray(lt.intensity, float))
                              for lt in scene.lights]
        # the room's light around the real objects (hidden truth); the array's absorber blocks it behind the array
        env = scene.environment
        self._room = None if env is None else EnvironmentLight(
            env.radiance_map(), self._world_to_array[:3, :3], samples=ROOM_SAMPLES, seed=self._seed + 5)
        self._ball_reflectance = tuple(scene.probe.ball_reflectance) if scene.probe is not None else (1.0, 1.0, 1.0)
        cam = self._truth.camera
        self._cam_shape = (cam.device.height, cam.device.width)
        px = np.stack(np.meshgrid(np.arange(cam.device.width), np.arange(cam.device.height)), -1).reshape(-1, 2)
        k, d = cam.device.pixel_to_ray(array, px.astype(np.float64))
        self._pix = np.flatnonzero(k >= 0)                      # camera pixels behind a lenslet
        self._pix_lenslet = k[self._pix]
        self._pix_dir = d[self._pix].astype(np.float32)         # (P, 3), d_z > 0
        prj = self._truth.projector
        self._prj_encoder = self._truth.encoder(projector_samples, projector_samples)
        self._prj_codec = self._prj_encoder.codec                 # projector pixels <-> emitted light field
        self._info = RigInfo(lf_camera=(cam.device.width, cam.device.height), lf_camera_bits=cam.bits,
                             projector=(prj.device.width, prj.device.height), projector_bits=prj.bits,
                             view=tuple(scene.view.resolution), kind="sim")
        self._projected = self._info.black()
        self._projector_light: LightFieldLight | None = None
        self._projector_light_stale = False
        self._setup: Setup = RealScene()
        self._world = self._real                                  # what the array faces now
        self._boards = 0
        self.boards_held: list[np.ndarray] = []                 # (4, 4) where each board really stood (truth)
        self._view = scene.view
        self._view_sensor = mi.load_dict(sensor_dict(self._view.origin, self._view.target, self._view.up,
                                                     self._view.fov_deg, *self._view.resolution))

    # -- the Rig protocol ---------------------------------------------------------------------------------
    @property
    def info(self) -> RigInfo:
        return self._info

    @property
    def projector_shape(self) -> tuple[int, int]:
        """(height, width) of a projector image."""
        return self._info.projector_shape

    def setup(self, request: Setup) -> None:
        """Arrange the simulated world: the real scene (its objects posed at the request's time), a collimator, a
        white diffuser, the focal-plane diffuser, a board held by the (simulated) operator, who misplaces it by a
        hidden error (lit by the point light too when the request says ``point_light``), the mirror ball on its
        mount in the room's light (the view camera photographs it, path traced; the real objects away), or the
        clean plate (the real scene's lights, its objects away)."""
        if isinstance(request, Board) and request.light is not None and request.light >= len(self._point_lights):
            raise ValueError(f"Board.light: the scene has {len(self._point_lights)} point light(s); there is no "
                             f"light {request.light} (0-based) to switch on")
        if isinstance(request, Board):
            self._world = self._board_renderer(request)
        elif isinstance(request, MirrorBall):
            if self._room is None:
                raise ValueError("MirrorBall: the scene has no [environment] (the room's light) for the simulated "
                                 "rig to show in the ball")
            # the LF camera sees the empty room (the ball's mount stands beside the array, out of the lenslets' view)
            self._world = self._without_real_objects()
        elif isinstance(request, CleanPlate):       # the real objects away, everything else as it is
            self._world = self._without_real_objects()
        elif isinstance(request, RealScene) and request.time_s != self._time_s and self._world_scene.moving:
            self._real = self._real_renderer(request.time_s)
            self._world = self._real
        elif isinstance(request, (RealScene, Collimator, WhiteField, FocalPlaneDiffuser)):
            self._world = self._real if isinstance(request, RealScene) else None
        else:
            raise TypeError(f"SimRig.setup: not a set-up request: {request!r}")
        self._setup = request

    def start_frame(self, index: int) -> None:
        """Begin frame ``index`` of a sequence whose frames are independent (``lft render --mode converged``): the
        sensor noise of the frame's captures is drawn from the rig's seed and the frame's index alone, not from
        the captures made before, so a frame rendered by any worker of a cluster, in any order, is bit-identical
        to the same frame rendered in one process.

        Args:
            index: the frame's number in its sequence (>= 0).
        """
        if not (isinstance(index, (int, np.integer)) and index >= 0):
            raise ValueError(f"SimRig.start_frame: frame index must be an integer >= 0, got {index!r}")
        self._rng = np.random.default_rng([self._seed, 7, int(index)])

    def noise_state(self) -> dict:
        """The state of the rig's random streams (sensor noise, the operator's hand), JSON-ready: what a run that
        reuses a cached calibration restores (:meth:`restore_noise_state`), so that it draws the noise the run that
        calibrated drew after calibrating."""
        return {"sensor": self._rng.bit_generator.state, "boards": int(self._boards)}

    def restore_noise_state(self, state: dict) -> None:
        """Set the random streams to ``state`` (:meth:`noise_state`)."""
        try:
            rng = np.random.default_rng()
            rng.bit_generator.state = state["sensor"]
            boards = int(state["boards"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"SimRig.restore_noise_state: not a noise state ({exc})") from None
        self._rng, self._boards = rng, boards

    def place_real(self, objects) -> None:
        """Put the real objects somewhere else (the interactive viewer's hand on the simulated world).

        Args:
            objects: the real objects (``ObjectConfig``), validated against the scene like a scene file's.

        Raises:
            SceneError: an object outside the real half-space, or otherwise invalid.

        The rigs of a scene's other interfaces (:meth:`join`) share the real world: they see the objects moved too.
        """
        from lftransfer.scenes import with_overrides

        for rig in (self, *self._siblings):
            rig._world_scene = with_overrides(rig._world_scene, real=list(objects))
            rig._real = rig._real_renderer(rig._time_s)
            if isinstance(rig._setup, RealScene):
                rig._world = rig._real

    @property
    def real_objects(self) -> list:
        """The real objects as they stand now (world frame; the simulator's hidden truth)."""
        return list(self._world_scene.real)

    def _without_real_objects(self) -> HalfSpaceRenderer:
        """The world in front of the array with the real objects taken away: the array's black absorber alone (it
        reflects nothing, so one bounce is all its light)."""
        return HalfSpaceRenderer([], extra_shapes=self._absorbers, max_depth=1)

    def _real_renderer(self, t: float) -> HalfSpaceRenderer:
        """The real objects posed at time ``t`` (seconds), seen from the true array's frame."""
        posed = scene_in_frame(self._world_scene.at(t), self._world_to_array)
        self._time_s = float(t)
        return HalfSpaceRenderer(posed.real, extra_shapes=self._absorbers, max_depth=posed.render.max_depth)

    def project(self, image: np.ndarray) -> None:
        """Show a projector image ((H, W, 3) unsigned integers of the projector's bit depth)."""
        self._projected = self._info.check_projector_image(image).copy()
        self._projector_light_stale = True

    def capture_lf(self, request: LFCapture = LFCapture()) -> LFFrame:
        """LF camera image of the current set-up (a mean of ``request.frames`` noisy frames)."""
        radiance = self.lf_signal() * np.float32(request.exposure_scale)
        codes = self.expose_lf(radiance, request.frames)
        return LFFrame(codes=codes, bits=self._truth.camera.bits, exposure_scale=request.exposure_scale)

    def lf_signal(self) -> np.ndarray:
        """(H, W, 3) float32 radiance reaching the LF camera's pixels in the current set-up and projection, before
        exposure and sensor noise (the device twin, :mod:`lftransfer.sim.twin`, exposes it once per frame)."""
        if isinstance(self._setup, Collimator):
            return self._collimated_radiance(self._setup.direction)
        if isinstance(self._setup, WhiteField):
            return self._white_radiance()
        if isinstance(self._setup, FocalPlaneDiffuser):
            return self._focal_plane_radiance(self._setup.transmission)
        return self._lf_radiance(self._world, self._setup_lights())

    def expose_lf(self, radiance: np.ndarray, frames: int = 1) -> np.ndarray:
        """LF camera codes of ``radiance`` ((H, W, 3) float32, exposure scale applied): the mean of ``frames``
        noisy exposures, (H, W, 3) uint16 codes of the camera's bit depth."""
        return self._expose_frames(radiance, frames)

    def capture_view(self, request: ViewCapture = ViewCapture()) -> ViewFrame:
        """View camera image ((H, W, 3) float32 linear radiance) of the current set-up.

        A simulated view camera has no sensor noise; ``request.quality`` is its samples per pixel.
        """
        w, h = self._view.resolution
        if isinstance(self._setup, MirrorBall):
            return ViewFrame(radiance=self._ball_photo(self._setup, request.quality or BALL_SPP))
        if self._world is None:                       # collimator or diffusers: the view camera sees darkness
            return ViewFrame(radiance=np.zeros((h, w, 3), np.float32))
        lights = self._setup_lights()
        img = self._world.render_view(self._view_sensor, w, h, lights, spp=request.quality or self.view_spp,
                                      seed=self._seed)
        return ViewFrame(radiance=img.rgb)

    def photograph_from(self, view, spp: int):
        """The real scene as another camera would photograph it, projector black (test light fields of known depth:
        :mod:`lftransfer.sim.views`); the rig's set-up and projection are left as they are.

        Args:
            view: the camera (``lftransfer.scenes.ViewConfig``, world frame).
            spp: rays per pixel.

        Returns:
            ``ViewImage`` (rgb radiance, alpha, depth: distance along each pixel's rays to the real objects, inf where
            none).
        """
        from lftransfer.backend import mitsuba

        m = self._world_to_array
        origin, target = (m[:3, :3] @ np.asarray(p, float) + m[:3, 3] for p in (view.origin, view.target))
        sensor = mitsuba().load_dict(sensor_dict(origin, target, m[:3, :3] @ np.asarray(view.up, float), view.fov_deg,
                                                 *view.resolution))
        return self._real.render_view(sensor, *view.resolution, self._scene_lights(), spp=spp, seed=self._seed)

    def close(self) -> None:
        """Nothing to release."""

    # -- the simulated physics ----------------------------------------------------------------------------------
    def _own_projector_light(self) -> LightFieldLight | None:
        """This interface's projector as a light of the real side (its array's frame), or None while it is dark."""
        if self._projector_light_stale:
            self._projector_light_stale = False
            radiance = self._prj_encoder.emitted(self._projected)         # (H, W, 3) radiance per projector pixel
            lf = self._prj_codec.image_to_lightfield(radiance)            # what each lenslet emits, per direction
            self._projector_light = None
            if np.any(lf.data != 0):
                self._projector_light = LightFieldLight(lf, side="real", model="area",
                                                        aperture_samples=self.aperture_samples, seed=self._seed + 3)
        return self._projector_light

    def _projector_lights(self) -> list:
        """Every interface's projector lighting the real side, in this array's frame."""
        own = self._own_projector_light()
        return [*([own] if own is not None else []), *(light for _, light in self._sibling_lights())]

    # -- several interfaces ---------------------------------------------------------------------------------
    def join(self, rigs: list) -> None:
        """Share the real world with the rigs of the scene's other interfaces (``rigs``, this one among them): their
        arrays stand in it (black absorbers behind their lenslets), their projectors light it, and this LF camera
        sees what they project where it looks at their lenslets."""
        self._siblings = [r for r in rigs if r is not self]
        for r in self._siblings:
            self._absorbers[f"lens_array_absorber_{r.interface}"] = lens_array_absorber(
                r.truth.array, to_world=self._from_sibling(r))
        self._real = self._real_renderer(self._time_s)
        if isinstance(self._setup, RealScene):
            self._world = self._real

    def _from_sibling(self, rig) -> np.ndarray:
        """(4, 4) another interface's array frame -> this array's frame."""
        return self._world_to_array @ np.linalg.inv(rig._world_to_array)

    def _sibling_lights(self) -> list:
        """(rig, its projector seen from this array's frame) for every other interface whose projector is lit; the
        posed copies are kept while their projection stays."""
        kept = self._posed_siblings
        out = []
        for r in self._siblings:
            light = r._own_projector_light()
            if light is None:
                continue
            if kept.get(r.interface, (None,))[0] is not light:
                kept[r.interface] = (light, light.seen_from(self._from_sibling(r)))
            out.append((r, kept[r.interface][1]))
        return out

    def _siblings_seen(self, origins: np.ndarray, directions: np.ndarray, distance: np.ndarray) -> np.ndarray:
        """(N, 3) float64 the light of the other interfaces' projectors along rays of this array's frame that meet
        their lenslets before anything else (``distance``: where each ray hits, inf where none)."""
        from lftransfer.backend import mitsuba
        from lftransfer.render.lights import jit_rays, to_numpy
        from lftransfer.render.windows import Windows

        mi = mitsuba()
        out = np.zeros((len(origins), 3), np.float64)
        for r, light in self._sibling_lights():
            crossing = Windows.of([r.truth.array], [light.pose]).crossed(origins, directions, distance)
            idx = np.flatnonzero(crossing)
            if not len(idx):
                continue
            rays = jit_rays(origins[idx], directions[idx])
            out[idx] += to_numpy(light.incident(rays.o, rays.d, mi.Bool(True)).radiance)
        return out

    def _scene_lights(self) -> list:
        """The real scene's own lights: the point lights and the room (where the scene has one)."""
        return [*self._point_lights, *([] if self._room is None else [self._room])]

    def _lights(self):
        return [*self._scene_lights(), *self._projector_lights()]

    def _ball_photo(self, ball: MirrorBall, spp: int) -> np.ndarray:
        """(H, W, 3) float32 the view camera's image of the mirror ball in the room's light, the lens array's
        absorber behind it, path traced by Mitsuba (a mirror needs the BSDF-sampled paths the renderer's
        next-event estimation leaves out)."""
        from lftransfer.backend import mitsuba

        mi = mitsuba()
        view, (w, h) = self._view, self._view.resolution
        m = np.eye(4)
        m[:3, :3] = self._world_to_array[:3, :3]
        # the ball's mount stands where it was measured in the world; the simulated rig sees it from its true frame
        centre = (self._world_to_array @ np.append(np.asarray(ball.centre, float), 1.0))[:3]
        scene = mi.load_dict({
            "type": "scene", "integrator": {"type": "path", "max_depth": 4},
            "sensor": sensor_dict(view.origin, view.target, view.up, view.fov_deg, w, h, spp=spp),
            "room": {"type": "envmap", "bitmap": mi.Bitmap(self._room.radiance),
                     "to_world": mi.ScalarTransform4f(m.tolist())},
            "ball": {"type": "sphere", "center": centre.tolist(), "radius": ball.radius,
                     "bsdf": {"type": "conductor", "material": "none",
                              "specular_reflectance": {"type": "rgb", "value": list(self._ball_reflectance)}}},
            **self._absorbers})
        return np.array(mi.render(scene, spp=spp, seed=self._seed + 11), np.float32)[..., :3]

    def _setup_lights(self) -> list:
        """The lights of the current set-up: the point lights (where they really stand) and the projector in the
        real scene; on a board asked for with the point light on, the one it names (all where it names none)
        and the projector; the room and the projector for the mirror ball; the real scene's for its clean
        plate; the projector alone otherwise."""
        if isinstance(self._setup, Board) and self._setup.point_light:
            i = self._setup.light
            on = self._point_lights if i is None else self._point_lights[i:i + 1]
            return [*on, *self._projector_lights()]
        if isinstance(self._setup, MirrorBall):
            return [self._room, *self._projector_lights()]
        return self._lights() if isinstance(self._setup, (RealScene, CleanPlate)) else self._projector_lights()

    def _expose_frames(self, radiance: np.ndarray, frames: int) -> np.ndarray:
        cam = self._truth.camera
        if frames == 1:
            return cam.expose(radiance, noise=self._sensor_noise)
        acc = np.zeros(radiance.shape, np.float64)
        for _ in range(frames):
            acc += cam.expose(radiance, noise=self._sensor_noise)
        return np.round(acc / frames).astype(np.uint16)

    def _lf_radiance(self, renderer: HalfSpaceRenderer, lights) -> np.ndarray:
        """(H, W, 3) float32 radiance at the LF camera's pixels: each pixel averages its ray direction over its
        lenslet's aperture."""
        array = self._truth.array
        centres = array.centres[self._pix_lenslet]                 # (P, 2)
        key = (len(self._pix), self.capture_spp)
        if getattr(self, "_offsets_key", None) != key:          # the same points for every capture: drawn once
            self._offsets = aperture_offsets(array, len(self._pix), self.capture_spp, seed=self._seed + 101)
            self._offsets_key = key
        offsets = self._offsets                                      # (P, S, 2)
        acc = np.zeros((len(self._pix), 3), np.float64)
        origins = np.zeros((len(self._pix), 3), np.float32)
        for s in range(self.capture_spp):
            origins[:, :2] = centres + offsets[:, s]
            radiance, _, distance = renderer.render_rays(origins, self._pix_dir, lights, seed=self._seed + s)
            acc += radiance
            if self._siblings:          # several interfaces: the others' lenslets, where this camera sees them
                acc += self._siblings_seen(origins, self._pix_dir, distance)
        image = np.zeros((self._cam_shape[0] * self._cam_shape[1], 3), np.float32)
        image[self._pix] = acc / self.capture_spp
        return image.reshape(*self._cam_shape, 3)

    def _sensor_noise(self, signal: np.ndarray) -> np.ndarray:
        """Shot noise (Poisson in electrons, ``full_well`` at full scale; its Gaussian limit above 64 electrons)
        plus Gaussian read noise."""
        rig = self._scene.rig
        electrons = np.clip(signal, 0, None) * rig.full_well
        # Poisson where few electrons arrive; its Gaussian limit (mean = variance) where many do, much faster
        many = electrons >= 64
        shot = np.where(many, electrons + np.sqrt(electrons) * self._rng.standard_normal(signal.shape, np.float32),
                        0.0)
        few = ~many
        shot[few] = self._rng.poisson(electrons[few])
        return shot / rig.full_well + self._rng.normal(0.0, rig.read_noise, signal.shape)

    def _collimated_radiance(self, direction, spot_sigma_px: float = 1.2) -> np.ndarray:
        """Radiance at the LF camera of a collimated source from ``direction`` (array frame; the collimator's
        tilt is set on its mount relative to the array).

        Every lenslet focuses the plane wave onto one point of its focal plane: on the array's axis its focal
        point, so the camera sees one spot per lenslet at the image of its optical centre; tilted, the spot
        moves by the (distorted) image of the beam's direction. Spots are as bright as the lenslet's
        aperture collects (peak at 70 % of full scale before vignetting).
        """
        array, cam = self._truth.array, self._truth.camera
        d = np.asarray(direction, np.float64)
        k = np.arange(array.K)
        spots = cam.device.ray_to_pixel(array, k, np.tile(d / np.linalg.norm(d), (array.K, 1)))    # (K, 2)
        # a beam outside a lenslet's field lands outside its cell: that lenslet shows no spot
        back = cam.device.pixel_to_ray(array, np.nan_to_num(spots, nan=-1e6))[0]
        spots = spots[back == k]
        h, w = self._cam_shape
        r = int(np.ceil(4 * spot_sigma_px))
        off = np.arange(-r, r + 1)
        cx, cy = np.round(spots[:, 0]).astype(int), np.round(spots[:, 1]).astype(int)
        xs = cx[:, None, None] + off[None, None, :]                       # (K, 1, n)
        ys = cy[:, None, None] + off[None, :, None]                       # (K, n, 1)
        weight = np.exp(-((xs - spots[:, 0, None, None]) ** 2 + (ys - spots[:, 1, None, None]) ** 2)
                        / (2 * spot_sigma_px ** 2))
        xs, ys = np.broadcast_arrays(xs, ys)
        inside = (xs >= 0) & (xs < w) & (ys >= 0) & (ys < h)
        image = np.zeros((h, w), np.float64)
        np.add.at(image, (ys[inside], xs[inside]), np.broadcast_to(weight, xs.shape)[inside])
        peak = 0.7 / (cam.exposure * np.max(weight))
        return np.repeat((image * peak)[..., None], 3, axis=2).astype(np.float32)

    def _white_radiance(self, level: float = 0.6) -> np.ndarray:
        """Radiance at the LF camera of an evenly lit white diffuser against the array: every pixel behind a
        lenslet sees the same radiance (60 % of full scale before vignetting)."""
        image = np.zeros((self._cam_shape[0] * self._cam_shape[1], 3), np.float32)
        image[self._pix] = level / self._truth.camera.exposure
        return image.reshape(*self._cam_shape, 3)

    def _focal_plane_radiance(self, transmission: float) -> np.ndarray:
        """Radiance at the LF camera of the projector's image on a diffuser at the lenslets' focal plane.

        Both devices image that plane, so the camera sees the projector's pixels directly (through its own
        homography and the projector's); the diffuser passes the fraction ``transmission`` of the light.
        """
        import cv2

        cam, prj = self._truth.camera.device, self._truth.projector.device
        if not hasattr(self, "_focal_map"):
            h, w = self._cam_shape
            px = np.stack(np.meshgrid(np.arange(w), np.arange(h)), -1).reshape(-1, 2).astype(np.float64)
            p = apply_homography(prj.homography @ np.linalg.inv(cam.homography), px)
            p = p.astype(np.float32).reshape(h, w, 2)
            self._focal_map = (p[..., 0].copy(), p[..., 1].copy())
        radiance = self._prj_encoder.emitted(self._projected)
        seen = cv2.remap(radiance, *self._focal_map, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=0)
        return np.float32(transmission) * seen

    def _hand_error(self) -> np.ndarray:
        """(4, 4) rigid error of the n-th board the operator holds: rotation about the board's centre and an offset
        (drawn from the operator seed and the board's number; never from the rig's truth)."""
        rng = np.random.default_rng([self._operator_seed, 31, self._boards])
        self._boards += 1
        m = np.eye(4)
        sigma = np.radians(self._operator.board_tilt_deg) / np.sqrt(3.0)
        m[:3, :3] = Rotation.from_rotvec(rng.normal(0.0, sigma, 3)).as_matrix()
        m[:3, 3] = rng.uniform(-self._operator.board_offset_m, self._operator.board_offset_m, 3)
        return m

    def _held(self, request: Board) -> np.ndarray:
        asked = rectangle_to_world(request.centre, request.normal, request.size)
        error = self._hand_error()
        held = asked.copy()
        held[:3, :3] = error[:3, :3] @ asked[:3, :3]
        held[:3, 3] = asked[:3, 3] + error[:3, 3]
        return held

    def _board_renderer(self, request: Board) -> HalfSpaceRenderer:
        held = self._held(request)
        self.boards_held.append(held)                            # rig frame (verification only)
        to_world = self._rig_to_array @ held
        shapes = {**self._absorbers, **board_shapes(
            to_world, request.albedo, request.chart, SCREEN_TRANSMISSION if request.translucent else 0.0)}
        return HalfSpaceRenderer([], extra_shapes=shapes, max_depth=1)

    # -- for verification only (never used by the pipeline) ------------------------------------------------
    @property
    def truth(self) -> RigModel:
        """The hidden true rig model. Only verification code may read it."""
        return self._truth
