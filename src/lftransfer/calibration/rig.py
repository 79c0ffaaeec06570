"""All calibration steps through the rig, in order, and the calibration file (paper, section 4.2).

1. lenslet centres: collimated on-axis source -> spots -> lattice (:mod:`.lenslets`); the LF camera's
   homography maps the rig file's nominal lattice (the *model frame*) onto the spots;
2. lenslet distortion: tilted collimator sweep (:mod:`.distortion`); the camera and the projector look through
   the same lenslets (a beam splitter), so both get it;
3. projector-to-camera mapping: Gray codes on a focal-plane diffuser (:mod:`.projector`); the projector's
   homography is that mapping after the camera's;
4. radiometry: responses, vignetting, cross-talk, black level, brightness and exposure (:mod:`.radiometric`);
5. global pose: projected fringes on boards the view camera sees (:mod:`.pose`), which carry the
   model frame into the world (array rotation, offset, pitch and tilt);
6. point lights (scenes with a ``[light]``): boards lit by one real point light alone, photographed by the view
   camera, give its position (:mod:`.light`), where the synthetic side's virtual twin of it is put; a scene with
   several lights measures each in turn.

The result is a :class:`Calibration`, whose :attr:`Calibration.model` is the rig model the pipeline uses, and
which is written as JSON in OpenCV's conventions (camera matrices, distortion ``k1 k2 p1 p2 k3``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from lftransfer.calibration.calibration_file import FORMAT, CalibrationFileError, parse_calibration_file
from lftransfer.calibration.distortion import DistortionFit, calibrate_distortion
from lftransfer.imageio_utils import to_grey
from lftransfer.calibration.lenslets import LatticeFit, find_lenslet_centres
from lftransfer.calibration.light import LightFit, calibrate_light, count_light_messages
from lftransfer.calibration.pose import FRINGE_SHIFTS, POSE_DEPTHS, POSE_ROUNDS, ArrayPose, apply_pose, calibrate_pose
from lftransfer.calibration.projector import (ProjectorCameraFit, decode_gray_code, fit_projector_camera,
                                              gray_code_patterns)
from lftransfer.calibration.radiometric import Radiometry, calibrate_radiometry
from lftransfer.imageio_utils import write_json
from lftransfer.optics import LensArray, LensletDevice
from lftransfer.optics.geometry import apply_homography, backproject
from lftransfer.rig.base import Rig
from lftransfer.rig.model import RigModel, nominal_rig
from lftransfer.rig.requests import Board, Collimator, FocalPlaneDiffuser, RealScene
from lftransfer.scenes import check_synthetic
from lftransfer.validation import read_json

__all__ = ["Calibration", "CalibrationFileError", "STEPS", "calibrate_exposure", "calibrate_rig",
           "calibration_from_json", "count_calibration_steps", "load_calibration"]

STEPS = ("lenslet centres", "lenslet distortion", "projector mapping", "radiometry", "global pose", "point light")


@dataclass
class Calibration:
    """A calibrated rig.

    Attributes:
        model: the rig model in the world (what the pipeline uses).
        lattice: the lenslet-centre fit (LF camera pixels).
        distortion: per-lenslet radial distortion.
        projector_fit: LF camera -> projector pixel homography.
        radiometry: responses, vignetting, cross-talk, black level, brightness, exposure.
        pose: the model frame's pose in the world.
        lights: the real point lights as measured (world frame), in the scene file's order; empty for a scene
            without one, or a calibration file from before the step existed: the scene file's positions then stand.
        diagnostics: images and measurements for the report (not saved).
    """

    model: RigModel
    lattice: LatticeFit | None
    distortion: DistortionFit | None
    projector_fit: ProjectorCameraFit | None
    radiometry: Radiometry
    pose: ArrayPose
    lights: list[LightFit] = field(default_factory=list)
    diagnostics: dict = field(default_factory=dict)

    def measures_lights(self, scene) -> bool:
        """Whether this calibration measured every point light of ``scene`` (a file from before the light step,
        or made for a scene with other lights, did not)."""
        return len(self.lights) == len(scene.lights)

    def light_positions(self, scene) -> list[tuple[float, float, float]]:
        """Where the synthetic side's point lights go (world frame, metres), one per light of the scene: the
        measured positions, else (:meth:`measures_lights` false) the scene file's."""
        measured = [fit.position for fit in self.lights] if self.measures_lights(scene) else \
            [lt.position for lt in scene.lights]
        return [tuple(float(v) for v in where) for where in measured]

    def unmeasured_light_note(self, scene, source) -> str | None:
        """One line of warning where the synthetic side's point lights stand where the scene file says because
        the calibration ``source`` has no (or no matching) light section, else None."""
        if not scene.lights or self.measures_lights(scene):
            return None
        return (f"{source}: no light section for the scene's {len(scene.lights)} point light(s) (it measured "
                f"{len(self.lights)}): the synthetic side's light stands where the scene file says, not where the "
                f"real one was measured; calibrate again (lft calibrate) to measure it")

    def to_json(self) -> dict:
        """The calibration as plain JSON data (OpenCV conventions for the per-lenslet cameras)."""
        m = self.model
        a = m.array
        data = {
            "format": FORMAT,
            "lens_array": {"lattice": a.lattice, "rows": a.rows, "cols": a.cols, "pitch_m": a.pitch,
                           "focal_length_m": a.focal_length, "aperture": a.aperture,
                           "offset_m": list(a.offset), "rotation_deg": float(np.degrees(a.rotation)),
                           "tilt_deg": np.degrees(m.tilt).tolist()},
            "pose": self.pose.to_json(),
            "lf_camera": _device_json(m.camera.device, a, bits=m.camera.bits),
            "projector": _device_json(m.projector.device, a, bits=m.projector.bits),
            "radiometry": self.radiometry.to_json(),
        }
        if self.lattice is not None:
            data["lenslet_centres"] = {"centres_px": self.lattice.centres.tolist(),
                                       "indices": self.lattice.indices.tolist(), "rms_px": self.lattice.rms_px,
                                       "pitch_px": self.lattice.pitch_px, "rotation_deg": self.lattice.rotation_deg}
        if self.distortion is not None:
            data["distortion"] = {"mount_angle_deg": float(np.degrees(self.distortion.mount_angle)),
                                  "rms": self.distortion.rms}
        if self.projector_fit is not None:
            data["projector_mapping"] = {"camera_to_projector": self.projector_fit.homography.tolist(),
                                         "rms_px": self.projector_fit.rms_px, "pixels": self.projector_fit.pixels}
        if len(self.lights) == 1:
            data["light"] = self.lights[0].to_json()          # one light: the section files have had since the step
        elif self.lights:
            data["lights"] = [fit.to_json() for fit in self.lights]
        return data

    def write(self, path) -> Path:
        """Write the JSON file atomically, as strict JSON (a measurement that is NaN is written as null)."""
        return write_json(path, self.to_json(), indent=1)


def _device_json(dev: LensletDevice, array: LensArray, bits: int) -> dict:
    """A device behind the array: its focal-plane homography and one OpenCV camera per lenslet.

    Each lenslet's ``camera_matrix`` is the first-order map from its normalised coordinates x_d (docs/architecture.md,
    "The interface": ``x_n = -(d_x, d_y) / d_z``) to pixels, at its centre; ``dist_coeffs`` are k1 k2 p1 p2 k3.
    """
    c = array.centres
    px = apply_homography(dev.homography, c)
    H = dev.homography
    # Jacobian of the homography at each centre, times the focal length: pixels per normalised unit
    w = np.concatenate([c, np.ones((len(c), 1))], 1) @ H[2]
    jac = (H[None, :2, :2] - px[:, :, None] * H[None, 2:3, :2]) / w[:, None, None] * array.focal_length
    cams = np.zeros((len(c), 3, 3))
    cams[:, :2, :2] = jac
    cams[:, :2, 2] = px
    cams[:, 2, 2] = 1.0
    dist = np.zeros((len(c), 5))
    dist[:, :2] = dev.distortion
    return {"width": dev.width, "height": dev.height, "bits": bits, "homography": dev.homography.tolist(),
            "lenslets": [{"camera_matrix": k.tolist(), "dist_coeffs": d.tolist()} for k, d in zip(cams, dist)]}


def load_calibration(path, scene) -> Calibration:
    """Read a calibration file written by :meth:`Calibration.write` for the scene's rig (a scene of several light
    field interfaces: :func:`lftransfer.calibration.interfaces.read_calibration`).

    The file is validated field by field (:mod:`lftransfer.calibration.calibration_file`: types, ranges, no
    unknown keys), then against the scene's rig: the array's lattice and size, the devices' sizes and bit depths,
    one lenslet camera per lenslet, the vignetting map's size.

    Args:
        path: the JSON file (UTF-8; a byte order mark is accepted).
        scene: the scene (or its synthetic part) whose ``rig`` the file must describe.

    Returns:
        Calibration (without the fits' details: ``lattice``, ``distortion`` and ``projector_fit`` are None).

    Raises:
        CalibrationFileError: unreadable file, malformed JSON, wrong format, an invalid field or a rig that does
            not match the scene's; one line naming the file and the field.
    """
    if scene.interfaces:
        raise TypeError("load_calibration reads one interface's calibration; a scene of several is read by "
                        "lftransfer.calibration.interfaces.read_calibration")
    path = Path(path)
    data = read_json(path, "calibration file", CalibrationFileError)
    if isinstance(data, dict) and "interfaces" in data:
        raise CalibrationFileError(f"{path}: interfaces: a calibration of several light field interfaces, but the "
                                   f"scene has one ([rig])")
    return calibration_from_json(data, str(path), scene)


def calibration_from_json(data, source: str, scene) -> Calibration:
    """A :class:`Calibration` from a calibration file's JSON value (:func:`load_calibration`; ``source`` names
    the file, or the file and the entry, in messages; ``scene``: whose ``rig`` it must describe)."""
    entry = parse_calibration_file(data, source)
    nominal = nominal_rig(scene.rig)
    _check_fits_scene(source, entry, nominal, scene)
    la = entry.lens_array

    def bad(field_name: str, exc: Exception) -> CalibrationFileError:
        return CalibrationFileError(f"{source}: {field_name}: {exc}")

    try:
        array = LensArray(lattice=la.lattice, rows=la.rows, cols=la.cols, pitch=la.pitch_m,
                          focal_length=la.focal_length_m, aperture=la.aperture, offset=tuple(la.offset_m),
                          rotation=float(np.radians(la.rotation_deg)))
    except (TypeError, ValueError) as exc:
        raise bad("lens_array", exc) from None

    def device(dev, name):
        k = np.array([lens.dist_coeffs[:2] for lens in dev.lenslets], float)
        try:
            return LensletDevice(width=dev.width, height=dev.height, homography=np.array(dev.homography, float),
                                 distortion=k)
        except (TypeError, ValueError) as exc:
            raise bad(name, exc) from None

    model = replace(nominal, array=array, tilt=tuple(np.radians(la.tilt_deg).tolist()),
                    camera=replace(nominal.camera, device=device(entry.lf_camera, "lf_camera")),
                    projector=replace(nominal.projector, device=device(entry.projector, "projector")))
    try:
        radiometry = Radiometry.from_json(entry.radiometry.model_dump())
        model = radiometry.apply(model)
    except (KeyError, TypeError, ValueError) as exc:
        raise bad("radiometry", exc) from None
    try:
        pose = ArrayPose.from_json({k: float("nan") if v is None else v for k, v in entry.pose.model_dump().items()})
    except (KeyError, TypeError, ValueError) as exc:
        raise bad("pose", exc) from None
    lights = []
    for i, light in enumerate(entry.light_entries()):
        try:
            lights.append(LightFit.from_json(light.model_dump()))
        except (KeyError, TypeError, ValueError) as exc:
            raise bad("light" if entry.light is not None else f"lights[{i}]", exc) from None
    return Calibration(model=model, lattice=None, distortion=None, projector_fit=None, radiometry=radiometry,
                       pose=pose, lights=lights)


def _check_fits_scene(path: str, entry, nominal: RigModel, scene) -> None:
    """A CalibrationFileError naming the first field of the file that does not fit the scene's rig."""
    la, a = entry.lens_array, nominal.array
    if (la.lattice, la.rows, la.cols) != (a.lattice, a.rows, a.cols):
        raise CalibrationFileError(
            f"{path}: lens_array: a {la.rows} x {la.cols} {la.lattice} array, but the scene's rig has "
            f"{a.rows} x {a.cols} {a.lattice}")
    want = {"lf_camera": (tuple(scene.rig.lf_camera), scene.rig.lf_camera_bits),
            "projector": (tuple(scene.rig.projector), scene.rig.projector_bits)}
    for name, (size, bits) in want.items():
        dev = getattr(entry, name)
        if (dev.width, dev.height) != size:
            raise CalibrationFileError(f"{path}: {name}.width, {name}.height: {dev.width} x {dev.height} pixels, "
                                       f"but the scene's rig has {size[0]} x {size[1]}")
        if dev.bits != bits:
            raise CalibrationFileError(f"{path}: {name}.bits: {dev.bits}, but the scene's rig has {bits}")
        if len(dev.lenslets) != a.K:
            raise CalibrationFileError(f"{path}: {name}.lenslets: {len(dev.lenslets)} lenslet cameras, but the "
                                       f"array has {a.rows} x {a.cols} = {a.K} lenslets")
    measured = entry.light_entries()
    if measured and len(measured) != len(scene.lights):
        field_name = "light" if entry.light is not None else "lights"
        raise CalibrationFileError(f"{path}: {field_name}: {len(measured)} point light(s) measured, but the scene has "
                                   f"{len(scene.lights)} ([light])")
    shape = entry.radiometry.vignetting.shape
    if tuple(shape) != (scene.rig.lf_camera[1], scene.rig.lf_camera[0]):
        raise CalibrationFileError(f"{path}: radiometry.vignetting.shape: {shape} ([height, width]), but the LF "
                                   f"camera is {scene.rig.lf_camera[1]} x {scene.rig.lf_camera[0]} ([height, width])")


EXPOSURE_LEVEL = 0.9              # the exposure step's projector level, of its range, before any clipping
EXPOSURE_MAX_INCIDENCE_DEG = 80.0  # LF camera rays meeting the exposure board farther than this from its normal are
                                   # left out (from behind, or grazing); none are on a board turned at most 53 degrees
EXPOSURE_TRIES = 5                # levels tried, each a quarter of the one before


def calibrate_exposure(rig: Rig, model: RigModel, scene, *, depth: float = 0.1, radius: float = 0.03,
                       albedo: float = 0.8) -> tuple[float, dict]:
    """The LF camera's absolute exposure, against the view camera (the radiometric reference).

    A grey diffuse board in front of the array, lit by the projector, has one radiance in every
    direction; the view camera and the LF camera (decoded with the model's exposure) both average it over the
    disc of ``radius`` around the board's centre. The ratio corrects the exposure.

    The projector lights the board through the lenslets, so its irradiance ripples with the lens pitch and the
    ripple's phase depends on the board's depth, which the operator's hand gets wrong by a few millimetres. An
    LF camera pixel averages over a whole lenslet aperture, a view pixel does not: the disc is wider than a
    lenslet (``radius`` > pitch) so that both average over the ripple, and the lit lenslets reach past it. An LF
    camera ray that meets the board more than :data:`EXPOSURE_MAX_INCIDENCE_DEG` from its normal is left out: on a
    board turned far from the array's axis (a view camera that faces the array, as with several interfaces), the
    lenslets' steepest rays meet it from behind, where it is unlit (7 % low on the enclosure's side interface).

    Returns:
        (exposure, diagnostics with both measurements).
    """
    from lftransfer.calibration.pose import board_pattern
    from lftransfer.lightfield import LightField

    board = board_pattern(scene.view, depth)
    # the LF camera rays that meet the board within the disc, and the view pixels that see the disc
    cam = model.camera.device
    step = max(1, int(np.sqrt(cam.width * cam.height / 400_000)))
    ys, xs = np.mgrid[0:cam.height:step, 0:cam.width:step]
    px = np.stack([xs.ravel(), ys.ravel()], 1).astype(np.float64)
    k, d = cam.pixel_to_ray(model.array, px)
    ok = k >= 0
    origin = model.array.centres3d[k[ok]]
    dn = d[ok] @ board.normal
    lam = ((board.centre - origin) @ board.normal) / np.where(dn != 0, dn, np.nan)
    hit = origin + lam[:, None] * d[ok]
    facing = dn < -np.cos(np.radians(EXPOSURE_MAX_INCIDENCE_DEG))      # not from behind (unlit), not grazing
    on_disc = (lam > 0) & (np.linalg.norm(hit - board.centre, axis=1) < radius)
    near = on_disc & facing
    sel = px[ok][near].astype(int)
    vw, vh = scene.view.resolution
    vy, vx = np.mgrid[0:vh, 0:vw]
    vpx = np.stack([vx.ravel(), vy.ravel()], 1).astype(np.float64)
    seen = np.linalg.norm(backproject(scene.view, vpx, board.centre, board.normal) - board.centre, axis=1) < radius
    if near.sum() < 20 or seen.sum() < 20:
        raise ValueError("camera exposure: the board's centre is not seen by both cameras")
    # light from the lenslets that reach the board's centre (within the lenslets' window), the others dark:
    # the measurement needs one uniformly lit spot, and dark lenslets cost the simulated capture nothing. A level
    # that makes the LF camera clip on the disc would read its exposure low: the level is lowered until none does.
    n = scene.rig.angular_samples
    reach = depth * 1.2 * model.array.half_width + model.array.pitch + radius
    near_axis = np.linalg.norm(model.array.centres, axis=1) < reach
    full = 2 ** rig.info.lf_camera_bits - 1
    lit = LightField.zeros(model.array, n, n)
    lit.data[near_axis] = model.projector.max_radiance
    encode = model.encoder(n, n)
    rig.setup(Board(centre=board.centre, normal=board.normal, size=(0.2, 0.2), albedo=albedo))
    level = EXPOSURE_LEVEL
    for _ in range(EXPOSURE_TRIES):
        rig.project(encode(lit * level))
        raw = rig.capture_lf().codes
        clipped = float(np.mean(np.any(raw[sel[:, 1], sel[:, 0]] >= full, axis=-1)))
        if clipped == 0:
            break
        level /= 4
    else:
        rig.project(rig.info.black())
        raise ValueError(f"camera exposure: the LF camera clips on the lit board even with the projector at "
                         f"{level * 4:.2g} of its range ({100 * clipped:.0f} % of the rays); lower [rig] exposure")
    view_img = rig.capture_view().radiance
    rig.project(rig.info.black())
    view_radiance = view_img.reshape(-1, 3)[seen].astype(np.float64).mean(0)
    if not np.all(view_radiance > 0):
        raise ValueError("camera exposure: the board's centre is not seen by both cameras")
    radiance = model.decoder(4, 4).radiance_image(raw)                   # per pixel, with the model's exposure
    lf_radiance = radiance[sel[:, 1], sel[:, 0]].astype(np.float64).mean(0)
    ratio = float(np.mean(lf_radiance / view_radiance))
    return model.camera.exposure * ratio, {"view_radiance": view_radiance.tolist(),
                                           "lf_radiance": lf_radiance.tolist(), "rays": int(near.sum()),
                                           "rays_left_out": int((on_disc & ~facing).sum()),
                                           "view_pixels": int(seen.sum()), "projector_level": level}


def _as_projector_image(pattern: np.ndarray, rig: Rig) -> np.ndarray:
    """A grey (H, W) or (H, W, 3) uint8 pattern (0 and 255) as the projector's (H, W, 3) image of its bit depth."""
    pattern = np.asarray(pattern)
    if pattern.ndim == 2:
        pattern = np.repeat(pattern[..., None], 3, axis=2)
    levels = 2 ** rig.info.projector_bits - 1
    if levels != 255:
        pattern = np.round(pattern.astype(np.float64) * (levels / 255))
    return pattern.astype(rig.info.projector_dtype)


SWEEP_STEPS = 5                   # collimator tilts per axis
_RADIOMETRY_MESSAGES = 5          # progress messages of calibrate_radiometry
_POSE_MESSAGES = (1 + 2 * FRINGE_SHIFTS) * len(POSE_DEPTHS) * POSE_ROUNDS    # progress messages of calibrate_pose


def _gray_groups(scene) -> int:
    w, h = scene.rig.projector
    return -(-len(gray_code_patterns(w, h)) // 8)


def count_calibration_steps(scene) -> int:
    """Progress messages of :func:`calibrate_rig` (for a progress bar; a scene of several interfaces:
    :func:`lftransfer.calibration.interfaces.count_steps`)."""
    return 1 + SWEEP_STEPS ** 2 + _gray_groups(scene) + _RADIOMETRY_MESSAGES + 1 + _POSE_MESSAGES \
        + count_light_messages(scene)


def check_rig_matches(rig: Rig, scene) -> None:
    """A ValueError unless the rig's devices are those the scene's rig file describes."""
    info, r = rig.info, scene.rig
    want = {"LF camera size": (tuple(r.lf_camera), info.lf_camera), "projector size": (tuple(r.projector), info.projector),
            "LF camera bits": (r.lf_camera_bits, info.lf_camera_bits),
            "projector bits": (r.projector_bits, info.projector_bits),
            "view camera size": (tuple(scene.view.resolution), info.view)}
    wrong = [f"{name}: the scene file says {a}, the {info.kind} rig has {b}" for name, (a, b) in want.items()
             if tuple(np.atleast_1d(a)) != tuple(np.atleast_1d(b))]
    if wrong:
        raise ValueError("the rig does not match the scene's [rig] and [view]: " + "; ".join(wrong))


def calibrate_rig(rig: Rig, scene, *, progress: Callable[[str], None] | None = None,
                  walls: np.ndarray | None = None) -> Calibration:
    """Run every calibration step through the rig (images only; the rig file's nominal values as the start).

    Args:
        rig: any :class:`~lftransfer.rig.base.Rig`; the steps ask it for set-ups (collimator, focal-plane
            diffuser, boards), projections and captures, and leave it in the real scene with the projector black.
        scene: the synthetic part of the scene (``SceneConfig.synthetic_part()``): the rig file's nominal
            values, the view camera and the point lights as the scene file places them (the last step's start).
        progress: called with a message per capture or step.
        walls: (N, 4) the planes of the scene's other light field interfaces in this one's frame, which the
            boards keep clear of (:func:`lftransfer.scenes.interfaces.walls`); None for a scene of one interface.

    Returns:
        Calibration (``lights`` empty for a scene without a point light).
    """
    say = progress or (lambda msg: None)
    check_rig_matches(rig, check_synthetic(scene))
    nominal = nominal_rig(scene.rig)
    array = nominal.array
    levels = nominal.camera.levels
    diag: dict = {}

    # 1. lenslet centres -> LF camera homography (model frame = the nominal lattice)
    say("lenslet centres: collimated source")
    rig.project(rig.info.black())
    rig.setup(Collimator())
    spots_img = rig.capture_lf().codes
    lattice = find_lenslet_centres(to_grey(spots_img, levels), array.lattice, expected_shape=(array.rows, array.cols))
    k = lattice.indices[:, 0] * array.cols + lattice.indices[:, 1]
    H_cam, _ = cv2.findHomography(array.centres[k], lattice.centres, 0)
    cam_w, cam_h = scene.rig.lf_camera
    camera = LensletDevice(width=cam_w, height=cam_h, homography=H_cam / H_cam[2, 2], distortion=np.zeros((array.K, 2)))
    diag["collimated"] = spots_img

    # 2. distortion through the lenslets
    distortion = calibrate_distortion(rig, array, camera, levels, steps=SWEEP_STEPS, progress=say)
    camera = replace(camera, distortion=distortion.coefficients)

    # 3. projector <-> camera
    prj_w, prj_h = scene.rig.projector
    captures = []
    patterns = gray_code_patterns(prj_w, prj_h)
    rig.setup(FocalPlaneDiffuser())
    for i, p in enumerate(patterns):
        if i % 8 == 0:
            say(f"projector mapping: Gray code {i + 1}-{min(i + 8, len(patterns))} of {len(patterns)}")
        rig.project(_as_projector_image(p, rig))
        captures.append(rig.capture_lf().codes.astype(np.float32).mean(axis=2) / levels)
    col, row, valid = decode_gray_code(captures, prj_w, prj_h)
    prj_fit = fit_projector_camera(col, row, valid)
    H_prj = prj_fit.homography @ camera.homography
    projector = LensletDevice(width=prj_w, height=prj_h, homography=H_prj / H_prj[2, 2],
                              distortion=distortion.coefficients)
    model = replace(nominal, camera=replace(nominal.camera, device=camera),
                    projector=replace(nominal.projector, device=projector))

    # 4. radiometry
    radiometry = calibrate_radiometry(rig, model, scene, progress=say, walls=walls)
    model = radiometry.apply(model)
    say("camera exposure: the LF camera and the view camera see the same board")
    radiometry.camera_exposure, diag["exposure"] = calibrate_exposure(rig, model, scene)
    model = radiometry.apply(model)

    # 5. global pose
    pose, pose_diag = calibrate_pose(rig, model, scene, progress=say, walls=walls)
    diag["pose"] = pose_diag
    model = apply_pose(model, pose)

    # 6. the point lights, one by one (their black level's light taken out with the calibrated projector)
    lights, diag["lights"] = [], []
    for i in range(len(scene.lights)):
        fit, light_diag = calibrate_light(rig, model, scene, light=i, progress=say)
        lights.append(fit)
        diag["lights"].append(light_diag)
    rig.project(rig.info.black())
    rig.setup(RealScene())
    return Calibration(model=model, lattice=lattice, distortion=distortion, projector_fit=prj_fit,
                       radiometry=radiometry, pose=pose, lights=lights, diagnostics=diag)
