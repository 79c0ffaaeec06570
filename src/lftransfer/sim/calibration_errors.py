"""A calibration's errors against the simulated rig's hidden truth (verification only; the faces reach it
through :meth:`lftransfer.sim.oracle.Oracle.calibration_errors`). The keys are those of the project's targets
(:mod:`lftransfer.calibration.targets`).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from lftransfer.optics.geometry import apply_homography, rotation_xy, rotation_z

__all__ = ["CalibrationErrors", "InterfacesCalibrationErrors", "calibration_errors", "interfaces_calibration_errors"]


def _rig_rotation(model) -> np.ndarray:
    return rotation_xy(model.tilt) @ rotation_z(model.array.rotation)


def _angle_deg(ra: np.ndarray, rb: np.ndarray) -> float:
    """The angle between two (3, 3) rotations, degrees."""
    return float(np.degrees(np.arccos(np.clip((np.trace(ra.T @ rb) - 1) / 2, -1, 1))))


@dataclass(frozen=True)
class CalibrationErrors:
    """A calibration against the simulated rig's hidden truth (:func:`calibration_errors`; verification only). The
    keys of ``to_json()`` are those of the project's targets (:mod:`lftransfer.calibration.targets`).

    Attributes:
        lenslet_assignment_agreement: fraction of camera pixels assigned to the right lenslet.
        ray_direction_rms_deg: each camera pixel's ray in the world, RMS angle, degrees.
        projector_mapping_rms_px: camera -> projector mapping, RMS, projector px.
        pose_position_rms_mm, pose_position_max_mm: the lenslet centres in the world, mm.
        pose_rotation_deg: the array's orientation, degrees.
        pitch_rel_error: calibrated / true pitch - 1.
        distortion_k1_rms: per-lenslet k1, RMS.
        camera_response_error, projector_response_error: responses, max, fraction of full scale.
        projector_mixing_rel_error: brightness x cross-talk, max, relative.
        black_level_error: projector black level, max, fraction of its max radiance.
        exposure_rel_error: LF camera exposure, relative.
        lenslet_centre_rms_px, lenslet_centre_max_px, lenslets_found: lenslet centres, LF camera px (None: the
            calibration has no lattice fit, e.g. read from a file).
        camera_gain_rel_rms: exposure x vignetting per pixel, RMS relative (None without vignetting).
        light_position_error_mm: the measured point lights against the true ones, the worst light, mm (None: not
            measured).
    """

    lenslet_assignment_agreement: float
    ray_direction_rms_deg: float
    projector_mapping_rms_px: float
    pose_position_rms_mm: float
    pose_position_max_mm: float
    pose_rotation_deg: float
    pitch_rel_error: float
    distortion_k1_rms: float
    camera_response_error: float
    projector_response_error: float
    projector_mixing_rel_error: float
    black_level_error: float
    exposure_rel_error: float
    lenslet_centre_rms_px: float | None = None
    lenslet_centre_max_px: float | None = None
    lenslets_found: int | None = None
    camera_gain_rel_rms: float | None = None
    light_position_error_mm: float | None = None

    def to_json(self) -> dict:
        """quantity -> error, the measured ones only (``calibration_errors.json``)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}


def calibration_errors(calibration, truth, *, true_lights=None, max_pixels: int = 200_000) -> CalibrationErrors:
    """Errors of a calibration against the simulated rig's hidden truth (verification only).

    Args:
        calibration: :class:`lftransfer.calibration.rig.Calibration`.
        truth: the true ``RigModel`` (``SimRig.truth``).
        true_lights: (3,) per point light, where it really stands, world frame, metres (the hidden world's
            ``lights``: :func:`lftransfer.sim.truth.true_light_scene`), in the scene file's order, or None.
        max_pixels: camera pixels sampled for the ray and mapping errors.

    Returns:
        :class:`CalibrationErrors`; ``light_position_error_mm`` (the worst light) where the calibration measured
        the lights and ``true_lights`` are given.
    """
    from lftransfer.calibration.radiometric import response_error

    cal = calibration.model
    out: dict = {}
    ta, ca = truth.array, cal.array
    tcam, ccam = truth.camera, cal.camera
    if calibration.lattice is not None:
        lat = calibration.lattice
        k = lat.indices[:, 0] * ta.cols + lat.indices[:, 1]
        true_px = tcam.device.ray_to_pixel(ta, k, np.tile([0.0, 0.0, 1.0], (len(k), 1)))
        err = np.linalg.norm(lat.centres - true_px, axis=1)
        out["lenslet_centre_rms_px"] = float(np.sqrt(np.mean(err ** 2)))
        out["lenslet_centre_max_px"] = float(err.max())
        out["lenslets_found"] = int(len(k))
    # camera pixels behind lenslets, a sample
    h, w = tcam.device.height, tcam.device.width
    rng = np.random.default_rng(0)
    px = np.stack([rng.uniform(0, w - 1, max_pixels), rng.uniform(0, h - 1, max_pixels)], 1)
    kt, dt = tcam.device.pixel_to_ray(ta, px)
    kc, dc = ccam.device.pixel_to_ray(ca, px)
    both = (kt >= 0) & (kc >= 0)
    same = both & (kt == kc)
    out["lenslet_assignment_agreement"] = float(same.sum() / max(both.sum(), 1))
    rt, rc = _rig_rotation(truth), _rig_rotation(cal)
    dw_t, dw_c = dt[same] @ rt.T, dc[same] @ rc.T                       # world directions
    ang = np.degrees(np.arccos(np.clip(np.sum(dw_t * dw_c, axis=1), -1, 1)))
    out["ray_direction_rms_deg"] = float(np.sqrt(np.mean(ang ** 2)))

    def to_prj(model, p):
        return apply_homography(model.projector.device.homography @ np.linalg.inv(model.camera.device.homography), p)

    inside = kt >= 0
    e = np.linalg.norm(to_prj(cal, px[inside]) - to_prj(truth, px[inside]), axis=1)
    out["projector_mapping_rms_px"] = float(np.sqrt(np.mean(e ** 2)))
    # global pose: the lenslet centres in the world, and the array's orientation
    ct, cc = ta.centres3d @ rotation_xy(truth.tilt).T, ca.centres3d @ rotation_xy(cal.tilt).T   # rotated in-plane
    d = np.linalg.norm(ct - cc, axis=1) * 1000
    out["pose_position_rms_mm"] = float(np.sqrt(np.mean(d ** 2)))
    out["pose_position_max_mm"] = float(d.max())
    out["pose_rotation_deg"] = _angle_deg(rc, rt)
    out["pitch_rel_error"] = float(ca.pitch / ta.pitch - 1)
    kd = np.asarray(ccam.device.distortion) - np.asarray(tcam.device.distortion)
    out["distortion_k1_rms"] = float(np.sqrt(np.mean(kd[:, 0] ** 2)))
    # radiometry
    out["camera_response_error"] = response_error(ccam.response, tcam.response)
    out["projector_response_error"] = response_error(cal.projector.response, truth.projector.response)
    tp, cp = truth.projector, cal.projector

    mt, mc = tp.max_radiance * tp.cross_talk_matrix, cp.max_radiance * cp.cross_talk_matrix
    out["projector_mixing_rel_error"] = float(np.abs(mc - mt).max() / np.abs(mt).max())
    bt = tp.max_radiance * np.asarray(tp.black_level)
    bc = cp.max_radiance * np.asarray(cp.black_level)
    out["black_level_error"] = float(np.abs(bc - bt).max() / tp.max_radiance)
    out["exposure_rel_error"] = float(ccam.exposure / tcam.exposure - 1)
    if tcam.vignetting is not None and ccam.vignetting is not None:
        ys, xs = px[inside, 1].astype(int), px[inside, 0].astype(int)
        st = tcam.exposure * tcam.vignetting[ys, xs]
        sc = ccam.exposure * ccam.vignetting[ys, xs]
        out["camera_gain_rel_rms"] = float(np.sqrt(np.mean((sc / st - 1) ** 2)))
    fits = getattr(calibration, "lights", [])
    if fits and true_lights is not None and len(true_lights) == len(fits):
        out["light_position_error_mm"] = max(float(1000 * np.linalg.norm(fit.position - np.asarray(at, float)))
                                             for fit, at in zip(fits, true_lights))
    return CalibrationErrors(**out)


def _seen_from(model, first) -> tuple[np.ndarray, np.ndarray]:
    """(K, 3) ``model``'s lenslet centres and (3, 3) its array's orientation, in the frame of ``first``'s array
    (its placement, its tilt, then its in-plane offset and rotation)."""
    frame = np.linalg.inv(first.world_to_array())                 # the array plane's frame: placement, then tilt
    frame[:3, 3] += frame[:3, :2] @ np.asarray(first.array.offset, np.float64)
    frame[:3, :3] = frame[:3, :3] @ rotation_z(first.array.rotation)
    rel = np.linalg.inv(frame) @ np.linalg.inv(model.world_to_array())
    return model.array.centres3d @ rel[:3, :3].T + rel[:3, 3], rel[:3, :3] @ rotation_z(model.array.rotation)


@dataclass(frozen=True)
class InterfacesCalibrationErrors:
    """A calibration of several light field interfaces against the simulated rig's hidden truth.

    Attributes:
        names: the interfaces' names, in the scene's order.
        errors: each interface's :class:`CalibrationErrors` (its pose in the world; the point lights with the
            first).
        relative: per interface after the first, its array against the first's as the calibration places both
            (what light that crosses from one to the other depends on): ``relative_position_rms_mm`` and
            ``relative_position_max_mm`` (its lenslet centres in the first array's frame) and
            ``relative_rotation_deg``.
    """

    names: tuple[str, ...]
    errors: tuple[CalibrationErrors, ...]
    relative: tuple[dict, ...]

    def to_json(self) -> dict:
        """``{"interfaces": {name: quantity -> error}}``, the relative pose among the errors of the interfaces
        after the first."""
        out = {self.names[0]: self.errors[0].to_json()}
        for name, errors, rel in zip(self.names[1:], self.errors[1:], self.relative):
            out[name] = {**errors.to_json(), **rel}
        return {"interfaces": out}


def interfaces_calibration_errors(calibration, truths, *, true_lights=None) -> InterfacesCalibrationErrors:
    """Errors of a calibration of several interfaces
    (:class:`lftransfer.calibration.interfaces.InterfacesCalibration`) against each interface's true model
    (``truths``, in the scene's order); ``true_lights`` as for :func:`calibration_errors` (the first's)."""
    cals = calibration.interfaces
    errors = tuple(calibration_errors(c, t, true_lights=true_lights if i == 0 else None)
                   for i, (c, t) in enumerate(zip(cals, truths)))
    relative = []
    for c, t in zip(cals[1:], truths[1:]):
        xc, rc = _seen_from(c.model, cals[0].model)
        xt, rt = _seen_from(t, truths[0])
        d = np.linalg.norm(xc - xt, axis=1) * 1000
        relative.append({"relative_position_rms_mm": float(np.sqrt(np.mean(d ** 2))),
                         "relative_position_max_mm": float(d.max()), "relative_rotation_deg": _angle_deg(rc, rt)})
    return InterfacesCalibrationErrors(names=tuple(calibration.names), errors=errors, relative=tuple(relative))
