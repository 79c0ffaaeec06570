"""``SimRig``: a digital twin of the light field transfer rig.

It owns a hidden truth (the real objects and their materials, the point light, the true lens array and device
models, noise) and renders the real world physically with Mitsuba:

- the projector's lenslets are direction-dependent area lights (their aperture is the lattice cell), all
  summed at every shading point, with shadow rays (:class:`lftransfer.render.lights.LightFieldLight`);
- each LF camera pixel averages the radiance arriving along its ray direction over its lenslet's aperture;
- real-to-real interreflections come from path tracing inside the real half-space;
- the lens array is a black absorber just behind the interface plane;
- the LF camera adds shot and read noise, applies its response and quantises to its bit depth.

The Monte Carlo sampling of the real world uses the same seed for every capture, like a deterministic physical
process: its error then cancels when captures are differenced; sensor noise does not.
"""

from __future__ import annotations

import numpy as np

from lftransfer.render.camera import sensor_dict
from lftransfer.render.lights import LightFieldLight, PointLight
from lftransfer.render.renderer import HalfSpaceRenderer, aperture_offsets
from lftransfer.rig.model import RigModel, nominal_rig
from lftransfer.scenes.frame import scene_in_frame


def board_to_world(array, nominal_array, centre, normal, size) -> np.ndarray:
    """Where a board asked for in the nominal array's frame stands, in the array's own frame.

    The nominal frame's points are carried by the array's scale, rotation and offset relative to the nominal
    array (the frame a light field projected through ``array`` but rendered for ``nominal_array`` lives in).

    Args:
        array, nominal_array: ``LensArray`` as built and as the rig file says.
        centre: (3,) board centre, metres, nominal frame.
        normal: (3,) board normal.
        size: (width, height) of the board in nominal units.

    Returns:
        (4, 4) ``to_world`` of a Mitsuba ``rectangle`` ([-1, 1]^2, normal +z) for the board.
    """
    scale = array.pitch / nominal_array.pitch
    c, s = np.cos(array.rotation - nominal_array.rotation), np.sin(array.rotation - nominal_array.rotation)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    shift = np.array([*(np.asarray(array.offset) - np.asarray(nominal_array.offset)), 0.0])
    n = rot @ np.asarray(normal, np.float64)
    n /= np.linalg.norm(n)
    helper = np.array([0.0, 1.0, 0.0]) if abs(n[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    ex = np.cross(helper, n)
    ex /= np.linalg.norm(ex)
    ey = np.cross(n, ex)
    m = np.eye(4)
    m[:3, :3] = np.stack([ex * size[0] / 2 * scale, ey * size[1] / 2 * scale, n], axis=1)
    m[:3, 3] = scale * rot @ np.asarray(centre, np.float64) + shift
    return m


def absorber_dict(array) -> dict:
    """Mitsuba shape dict of the lens array seen from the real side: a black rectangle just behind z = 0."""
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    xmin, xmax, ymin, ymax = array.extent()
    return {"type": "rectangle",
            "to_world": mi.ScalarTransform4f().translate([(xmin + xmax) / 2, (ymin + ymax) / 2, -5e-4])
            .scale([(xmax - xmin) / 2, (ymax - ymin) / 2, 1.0]),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}}


class SimRig:
    """Simulated rig for a scene (``lftransfer.scenes.SceneConfig``).

    Args:
        scene: the scene; its ``real`` objects become the hidden real world.
        truth: true rig model; defaults to the rig file's nominal values.
        capture_spp: rays per LF camera pixel (points on the lenslet aperture).
        view_spp: rays per view camera pixel.
        projector_samples: angular resolution (per axis) at which each projector lenslet's emission is
            resampled from the projector image.
        aperture_samples: points per projector lenslet aperture for each shading point.
        seed: seed of the hidden truth's noise.

    Example:
        >>> rig = SimRig(load_scene(builtin_scene("fig4")))       # doctest: +SKIP
        >>> raw = rig.capture_lf()                                  # (1536, 2048, 3) uint16
    """

    def __init__(self, scene, *, truth: RigModel | None = None, capture_spp: int = 4, view_spp: int = 4,
                 projector_samples: int = 64, aperture_samples: int = 2, seed: int | None = None) -> None:
        from lftransfer.backend import mitsuba

        mi = mitsuba()
        self._truth = truth or nominal_rig(scene.rig)
        # The real world seen from the true lens array's own frame (interface plane z = 0).
        scene = scene_in_frame(scene, self._truth.world_to_array())
        self._scene = scene
        self._seed = int(scene.rig.seed if seed is None else seed)
        self._rng = np.random.default_rng(self._seed + 7)
        self.capture_spp = int(capture_spp)
        self.view_spp = int(view_spp)
        self.aperture_samples = int(aperture_samples)
        array = self._truth.array
        self._absorber = absorber_dict(array)
        self._real = HalfSpaceRenderer(scene.real, extra_shapes={"lens_array_absorber": self._absorber},
                                       max_depth=scene.render.max_depth)
        self._point_light = PointLight(np.asarray(scene.light.position, float), np.asarray(scene.light.intensity, float))
        cam = self._truth.camera
        self._cam_shape = (cam.device.height, cam.device.width)
        px = np.stack(np.meshgrid(np.arange(cam.device.width), np.arange(cam.device.height)), -1).reshape(-1, 2)
        k, d = cam.device.pixel_to_ray(array, px.astype(np.float64))
        self._pix = np.flatnonzero(k >= 0)                      # camera pixels behind a lenslet
        self._pix_lenslet = k[self._pix]
        self._pix_dir = d[self._pix].astype(np.float32)         # (P, 3), d_z > 0
        prj = self._truth.projector
        self._prj_shape = (prj.device.height, prj.device.width)
        self._prj_encoder = self._truth.encoder(projector_samples, projector_samples)
        self._prj_codec = self._prj_encoder.codec                 # projector pixels <-> emitted light field
        self._projector_light: LightFieldLight | None = None
        self._view = scene.view
        self._view_sensor = mi.load_dict(sensor_dict(self._view.origin, self._view.target, self._view.up,
                                                     self._view.fov_deg, *self._view.resolution))

    # -- the Rig protocol ---------------------------------------------------------------------------------
    @property
    def projector_shape(self) -> tuple[int, int]:
        return self._prj_shape

    @property
    def lf_camera_shape(self) -> tuple[int, int]:
        return self._cam_shape

    def project(self, image: np.ndarray) -> None:
        """Show a projector image ((H, W, 3) unsigned integers of the projector's bit depth)."""
        image = np.asarray(image)
        expected = (*self._prj_shape, 3)
        if image.shape != expected or image.dtype.kind != "u":
            raise ValueError(f"projector image must be {expected} unsigned integers, got {image.shape} {image.dtype}")
        radiance = self._prj_encoder.emitted(image)                # (H, W, 3) radiance of each projector pixel
        lf = self._prj_codec.image_to_lightfield(radiance)          # what each lenslet emits, per direction
        self._projector_light = None
        if np.any(lf.data != 0):
            self._projector_light = LightFieldLight(lf, side="real", model="area",
                                                    aperture_samples=self.aperture_samples, seed=self._seed + 3)

    def _projector_lights(self) -> list:
        return [self._projector_light] if self._projector_light is not None else []

    def _lights(self):
        return [self._point_light] + self._projector_lights()

    def capture_lf(self) -> np.ndarray:
        """LF camera image ((H, W, 3) uint16, ``bits``-bit codes) of the real world as it is lit now."""
        return self._capture_lf_with(self._real)

    def _capture_lf_with(self, renderer: HalfSpaceRenderer, lights=None) -> np.ndarray:
        lights = self._lights() if lights is None else lights
        array = self._truth.array
        centres = array.centres[self._pix_lenslet]                 # (P, 2)
        offsets = aperture_offsets(array, len(self._pix), self.capture_spp, seed=self._seed + 101)  # (P, S, 2)
        acc = np.zeros((len(self._pix), 3), np.float64)
        origins = np.zeros((len(self._pix), 3), np.float32)
        for s in range(self.capture_spp):
            origins[:, :2] = centres + offsets[:, s]
            radiance, _, _ = renderer.render_rays(origins, self._pix_dir, lights, seed=self._seed + s)
            acc += radiance
        image = np.zeros((self._cam_shape[0] * self._cam_shape[1], 3), np.float32)
        image[self._pix] = acc / self.capture_spp
        image = image.reshape(*self._cam_shape, 3)
        return self._truth.camera.expose(image, noise=self._sensor_noise)

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

    def capture_view(self) -> np.ndarray:
        """View camera image ((H, W, 3) float32 linear radiance) of the real world as it is lit now."""
        w, h = self._view.resolution
        img = self._real.render_view(self._view_sensor, w, h, self._lights(), spp=self.view_spp, seed=self._seed)
        return img.rgb

    # -- calibration actions (paper, section 4.2) -------------------------------------------------------------
    def capture_collimated(self, spot_sigma_px: float = 1.2, direction=(0.0, 0.0, 1.0)) -> np.ndarray:
        """LF camera image of a collimated light source (real world lights off).

        Every lenslet focuses the plane wave onto one point of its focal plane: on the array's axis its focal
        point, so the camera sees one spot per lenslet at the image of its optical centre; tilted, the spot
        moves by the (distorted) image of the beam's direction. Spots are as bright as the lenslet's
        aperture collects, times vignetting, with sensor noise.

        Args:
            spot_sigma_px: standard deviation of each spot's blur, camera pixels.
            direction: (3,) direction the beam comes from, in the array's frame (z > 0: the real side);
                the collimator's tilt is set on its mount, so it is known in the array's frame.

        Returns:
            (H, W, 3) uint16 camera codes.
        """
        array, cam = self._truth.array, self._truth.camera
        d = np.asarray(direction, np.float64)
        if d.shape != (3,) or not d[2] > 0:
            raise ValueError(f"direction must be a 3-vector with z > 0, got {direction!r}")
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
        # Peak at 70 % of full scale before vignetting (the exposure of this calibration shot).
        peak = 0.7 / (cam.exposure * np.max(weight))
        radiance = np.repeat((image * peak)[..., None], 3, axis=2).astype(np.float32)
        return cam.expose(radiance, noise=self._sensor_noise)

    def capture_focal_plane(self, image: np.ndarray, diffuser: float = 0.5,
                            exposure_scale: float = 1.0) -> np.ndarray:
        """LF camera image while the projector shows ``image`` onto a diffuser at the lenslets' focal plane.

        Both devices image that plane, so the camera sees the projector's pixels directly (through its own
        homography and the projector's); the diffuser passes the fraction ``diffuser`` of the light.
        ``exposure_scale`` is the camera's exposure time relative to its normal one (exposure bracketing):
        ``signal = exposure * exposure_scale * diffuser * L * vignetting``.

        Returns:
            (H, W, 3) uint16 camera codes.
        """
        import cv2

        if not (np.isfinite(exposure_scale) and exposure_scale > 0):
            raise ValueError(f"exposure_scale must be positive, got {exposure_scale!r}")
        image = np.asarray(image)
        expected = (*self._prj_shape, 3)
        if image.shape[:2] != self._prj_shape:
            raise ValueError(f"projector image must be {expected}, got {image.shape}")
        if image.ndim == 2:
            image = np.repeat(image[..., None], 3, axis=2)
        cam, prj = self._truth.camera.device, self._truth.projector.device
        if not hasattr(self, "_focal_map"):
            h, w = self._cam_shape
            px = np.stack(np.meshgrid(np.arange(w), np.arange(h)), -1).reshape(-1, 2).astype(np.float64)
            q = np.concatenate([px, np.ones((len(px), 1))], 1) @ np.linalg.inv(cam.homography).T
            p = q @ prj.homography.T
            p = (p[:, :2] / p[:, 2:3]).astype(np.float32).reshape(h, w, 2)
            self._focal_map = (p[..., 0].copy(), p[..., 1].copy())
        radiance = self._prj_encoder.emitted(image)
        seen = cv2.remap(radiance, *self._focal_map, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=0)
        return self._truth.camera.expose((exposure_scale * diffuser) * seen, noise=self._sensor_noise)

    def capture_board(self, image: np.ndarray, centre, normal, size=(0.3, 0.3), albedo: float = 0.8,
                      printed: tuple[int, int, float] | None = None, spp: int | None = None) -> np.ndarray:
        """View camera image of a diffuse board held in front of the array while the projector shows ``image``.

        The real objects are taken away and the point light is off. The operator holds the board where the
        projected image is sharp: the plane asked for, given in the frame the rig file's nominal array defines
        (centre of the array, nominal pitch), lies in the real world where the true array's scale, rotation and
        offset carry it.

        Args:
            image: (H, W, 3) projector codes.
            centre: (3,) board centre, metres, nominal array frame (z > 0: the real side).
            normal: (3,) board normal, pointing to the side the board is seen and lit from.
            size: (width, height) of the board, metres.
            albedo: the board's diffuse reflectance (a grey calibration target).
            printed: (columns, rows, square size in metres) of a chessboard printed on the board's centre (dark
                squares of reflectance ``albedo / 4``), a metric target for the view camera; None: plain board.
            spp: view camera samples per pixel (default: the rig's ``view_spp``).

        Returns:
            (h, w, 3) float32 linear radiance of the view camera.
        """
        self.project(image)
        renderer = self._board_renderer(centre, normal, size, albedo, printed)
        w, h = self._view.resolution
        img = renderer.render_view(self._view_sensor, w, h, self._projector_lights(), spp=spp or self.view_spp,
                                   seed=self._seed)
        return img.rgb

    def capture_board_lf(self, image: np.ndarray, centre, normal, size=(0.3, 0.3), albedo: float = 0.8) -> np.ndarray:
        """LF camera image of the board of :meth:`capture_board` (same placement) while the projector shows
        ``image``: the LF camera and the view camera see the same diffuse surface.

        Returns:
            (H, W, 3) uint16 camera codes.
        """
        self.project(image)
        return self._capture_lf_with(self._board_renderer(centre, normal, size, albedo, None),
                                     self._projector_lights())

    def _board_renderer(self, centre, normal, size, albedo, printed) -> HalfSpaceRenderer:
        from lftransfer.backend import mitsuba

        mi = mitsuba()
        to_world = board_to_world(self._truth.array, nominal_rig(self._scene.rig).array, centre, normal, size)
        ex, ey, n = (to_world[:3, i] / np.linalg.norm(to_world[:3, i]) for i in range(3))
        p = to_world[:3, 3]
        shapes = {"lens_array_absorber": self._absorber,
                  "board": {"type": "rectangle", "to_world": mi.ScalarTransform4f(to_world.tolist()),
                            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [albedo] * 3}}}}
        if printed is not None:
            cols, rows, square = printed
            chart = to_world.copy()
            chart[:3, 0] = ex * cols * square / 2             # printed at its true size (not the array's scale)
            chart[:3, 1] = ey * rows * square / 2
            chart[:3, 3] = p + 1e-4 * n
            texture = {"type": "checkerboard", "color0": {"type": "rgb", "value": [albedo / 4] * 3},
                       "color1": {"type": "rgb", "value": [albedo] * 3},
                       "to_uv": mi.ScalarTransform4f().scale([cols / 2, rows / 2, 1.0])}
            shapes["chart"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f(chart.tolist()),
                               "bsdf": {"type": "diffuse", "reflectance": texture}}
        return HalfSpaceRenderer([], extra_shapes=shapes, max_depth=1)

    # -- for verification only (never used by the pipeline) ------------------------------------------------
    @property
    def truth(self) -> RigModel:
        """The hidden true rig model. Only verification code may read it."""
        return self._truth
