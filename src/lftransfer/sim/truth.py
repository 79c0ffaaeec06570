"""Hidden truths for the simulated rig: a rig as built, away from the rig file's nominal values.

A real rig never matches its drawing: the lens array sits rotated and shifted, its pitch is off by a fraction
of a percent, each Fresnel lenslet distorts a little, the camera and the projector do not face the focal plane
squarely, responses differ per channel, the camera vignettes and its exposure is off, the projector is brighter
or dimmer than its data sheet, leaks light at code 0 and mixes its colour channels. :func:`perturbed_rig` draws
all of that from a seed; the simulated rig renders with it, and the pipeline must recover it by calibration
(only verification code may read it).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from lftransfer.lightfield import CameraModel, ProjectorModel, ResponseCurve
from lftransfer.optics import LensArray, LensletDevice
from lftransfer.optics.geometry import rotation_xy
from lftransfer.rig.model import RigModel, nominal_rig, placed


@dataclass(frozen=True)
class Perturbation:
    """Sizes of the deviations from the nominal rig (each drawn uniformly in +-size unless said otherwise).

    Attributes:
        rotation_deg: in-plane rotation of the lens array.
        offset_m: in-plane offset of the lens array, per axis.
        pitch_rel: relative pitch error (focal length scales with it).
        k1, k2: per-lenslet radial distortion, drawn around (k1_mean, 0) with these spreads.
        k1_mean: mean radial distortion of the Fresnel lenslets.
        view_tilt_deg: how far the camera and projector look away from the focal plane's normal.
        gamma_rel: relative deviation of each channel's response exponent.
        vignetting: relative fall-off of the camera's sensitivity at the image corners.
        tilt_deg: out-of-plane tilt of the lens array about the world x and y axes.
        light_error_m: error of the point light's position as the scene file gives it, per axis.
        cross_talk: projector colour cross-talk: off-diagonal entries of the (3, 3) matrix drawn in
            [0, cross_talk] (its diagonal is ``1 + uniform(-channel_gain_rel, channel_gain_rel)``).
        black_level: projector light at code 0, per channel ``uniform(0.2, 1) * black_level`` of max_radiance.
        exposure_rel: relative error of the camera's exposure.
        brightness_rel: relative error of the projector's max_radiance.
        channel_gain_rel: spread of the diagonal of the cross-talk matrix (per-channel brightness).
    """

    rotation_deg: float = 2.0
    offset_m: float = 0.003
    pitch_rel: float = 0.01
    k1: float = 0.02
    k2: float = 0.005
    k1_mean: float = -0.04
    view_tilt_deg: float = 3.0
    gamma_rel: float = 0.1
    vignetting: float = 0.3
    tilt_deg: float = 0.5
    light_error_m: float = 0.003
    cross_talk: float = 0.06
    black_level: float = 0.01
    exposure_rel: float = 0.1
    brightness_rel: float = 0.1
    channel_gain_rel: float = 0.05


def _tilted(device: LensletDevice, tilt_deg: float, rng: np.random.Generator) -> LensletDevice:
    """The same device looking at the focal plane from a little off its normal (a homography of a rotation)."""
    w, h = device.width, device.height
    f = 1.2 * max(w, h)                                  # focal length of the device in pixels (about 45 deg)
    ax, ay = np.radians(rng.uniform(-tilt_deg, tilt_deg, 2))
    k = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]])
    turn = rotation_xy((ax, 0.0)) @ rotation_xy((0.0, ay))          # R_x @ R_y
    warp = k @ turn @ np.linalg.inv(k)                   # image of the tilted view, about the image centre
    return replace(device, homography=warp @ device.homography)


def _vignetting(width: int, height: int, falloff: float) -> np.ndarray:
    """(H, W) float32 relative sensitivity: 1 at the centre, 1 - falloff at the corners (cos^4-like)."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    r2 = ((x - (width - 1) / 2) ** 2 + (y - (height - 1) / 2) ** 2) / (((width - 1) / 2) ** 2 + ((height - 1) / 2) ** 2)
    return (1.0 - falloff * r2).astype(np.float32)


def perturbed_rig(rig, seed: int, size: Perturbation = Perturbation()) -> RigModel:
    """A rig as built: the rig file's nominal rig with deviations drawn from ``seed``.

    Args:
        rig: ``lftransfer.scenes.RigConfig`` (nominal values).
        seed: random seed of the deviations.
        size: sizes of the deviations.

    Returns:
        RigModel of the true rig.
    """
    rng = np.random.default_rng(seed)
    nominal = nominal_rig(rig)
    scale = 1.0 + rng.uniform(-size.pitch_rel, size.pitch_rel)
    array = LensArray(lattice=rig.lattice, rows=rig.rows, cols=rig.cols, pitch=rig.pitch * scale,
                      focal_length=rig.focal_length * scale, aperture=rig.aperture,
                      offset=tuple(rng.uniform(-size.offset_m, size.offset_m, 2)),
                      rotation=float(np.radians(rng.uniform(-size.rotation_deg, size.rotation_deg))))
    K = array.K

    def distortion():
        return np.stack([size.k1_mean + rng.uniform(-size.k1, size.k1, K), rng.uniform(-size.k2, size.k2, K)], 1)

    def gamma(nominal_gamma):
        return tuple(float(g * (1 + rng.uniform(-size.gamma_rel, size.gamma_rel))) for g in nominal_gamma)

    cam, prj = nominal.camera, nominal.projector
    cam_device = _tilted(replace(cam.device, distortion=distortion()), size.view_tilt_deg, rng)
    distortion()      # (a draw kept so that later draws stay the same)
    # camera and projector look through the same lenslets (a beam splitter): one distortion for both
    prj_device = _tilted(replace(prj.device, distortion=cam_device.distortion), size.view_tilt_deg, rng)
    camera = CameraModel(device=cam_device, bits=cam.bits, response=ResponseCurve(gamma(rig.camera_gamma)),
                         exposure=cam.exposure, vignetting=_vignetting(cam_device.width, cam_device.height,
                                                                       size.vignetting))
    projector = ProjectorModel(device=prj_device, bits=prj.bits, response=ResponseCurve(gamma(rig.projector_gamma)),
                               max_radiance=prj.max_radiance)
    tilt = tuple(float(a) for a in np.radians(rng.uniform(-size.tilt_deg, size.tilt_deg, 2)))
    # Radiometry from its own generator, so that the draws above stay what they were before it existed.
    rad = np.random.default_rng([seed, 23])
    cross_talk = rad.uniform(0.0, size.cross_talk, (3, 3))
    cross_talk[np.diag_indices(3)] = 1.0 + rad.uniform(-size.channel_gain_rel, size.channel_gain_rel, 3)
    black_level = tuple(float(b) for b in rad.uniform(0.2, 1.0, 3) * size.black_level)
    exposure = cam.exposure * (1.0 + rad.uniform(-size.exposure_rel, size.exposure_rel))
    max_radiance = prj.max_radiance * (1.0 + rad.uniform(-size.brightness_rel, size.brightness_rel))
    camera = replace(camera, exposure=exposure)
    projector = replace(projector, max_radiance=max_radiance, cross_talk=cross_talk, black_level=black_level)
    return RigModel(array=array, camera=camera, projector=projector, tilt=tilt, placement=nominal.placement)


INTERFACE_SEED_STEP = 7919      # interface i's deviations are drawn from seed + i * this


def true_interfaces(scene, seed: int | None) -> list[RigModel] | None:
    """The true rig model of every interface of a scene for a hidden-truth seed (interface i's deviations drawn
    from ``seed + i * INTERFACE_SEED_STEP``; the first is :func:`perturbed_rig`'s); None for ``seed`` None (the
    rig file is exact)."""
    if seed is None:
        return None
    if not scene.interfaces:
        return [perturbed_rig(scene.rig, seed)]
    return [replace(perturbed_rig(face.rig(scene.rig), seed + i * INTERFACE_SEED_STEP),
                    placement=placed(face.to_world())) for i, face in enumerate(scene.interfaces)]


def hidden_world(scene, seed: int | None):
    """The world as it is for a hidden-truth seed, for the simulated rig and the ground truth only.

    Args:
        scene: the scene file's scene.
        seed: hidden-truth seed; None: the rig file and the scene file are exact.

    Returns:
        (scene with the point light where it really stands, true ``RigModel`` or None for the rig file's).
    """
    if seed is None:
        return scene, None
    return true_light_scene(scene, seed), perturbed_rig(scene.rig, seed)


def true_light_scene(scene, seed: int, size: Perturbation = Perturbation()):
    """The scene as it really is: every point light where it really stands, away from the file's position.

    The scene file's positions are measurements by hand; the truth differs by up to ``size.light_error_m`` per
    axis, drawn from ``seed`` for each light on its own (independently of :func:`perturbed_rig`).

    Returns:
        A new SceneConfig (for the simulated rig and the ground truth only); the scene itself when it has no
        point light.
    """
    from lftransfer.scenes import with_overrides

    if not scene.lights:
        return scene
    moved = []
    for i, light in enumerate(scene.lights):
        rng = np.random.default_rng([seed, 17] if i == 0 else [seed, 17, i])
        error = rng.uniform(-size.light_error_m, size.light_error_m, 3)
        moved.append(light.model_copy(update={"position": (np.asarray(light.position) + error).tolist()}))
    return with_overrides(scene, lights=moved)
