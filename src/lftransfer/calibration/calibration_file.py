"""The calibration file's schema (``lftransfer-calibration/1``): every field typed and ranged, unknown keys refused.

:func:`parse_calibration_file` validates the JSON value of a file written by
:meth:`lftransfer.calibration.rig.Calibration.write` and reports the first problems in one line, worded like
scene and rig files (:mod:`lftransfer.validation`): ``calibration.json: radiometry.camera_gamma[1]: Input should
be greater than 0, found -2.2``. Whether the file fits a scene's rig is checked by
:func:`lftransfer.calibration.rig.load_calibration`.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, Optional

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, Strict, ValidationError, field_validator, model_validator

from lftransfer.validation import validation_message

__all__ = ["FORMAT", "CalibrationFile", "CalibrationFileError", "LightEntry", "parse_calibration_file"]

FORMAT = "lftransfer-calibration/1"


class CalibrationFileError(ValueError):
    """A calibration file that cannot be read or does not fit the scene's rig; the message names the file and
    the field (``calibration.json: lens_array.rows: ...``)."""


Finite = Annotated[float, Strict(), Field(allow_inf_nan=False)]
Positive = Annotated[float, Strict(), Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Strict(), Field(ge=0, allow_inf_nan=False)]
Diagnostic = Optional[Annotated[float, Strict()]]          # a measurement kept for reports: may be NaN or null
PosInt = Annotated[int, Strict(), Field(gt=0)]
NonNegInt = Annotated[int, Strict(), Field(ge=0)]
Vec2 = Annotated[list[Finite], Field(min_length=2, max_length=2)]
Vec3 = Annotated[list[Finite], Field(min_length=3, max_length=3)]
PosVec3 = Annotated[list[Positive], Field(min_length=3, max_length=3)]
Matrix3 = Annotated[list[Vec3], Field(min_length=3, max_length=3)]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


def _invertible(m: list[list[float]]) -> list[list[float]]:
    det = float(np.linalg.det(np.asarray(m, float)))
    if not np.isfinite(det) or abs(det) < 1e-300:
        raise ValueError(f"a homography must be invertible, found determinant {det:.3g}")
    return m


class LensArrayEntry(_Model):
    """``lens_array``: the calibrated array in the world (metres, degrees)."""

    lattice: Literal["hex", "rect"]
    rows: PosInt
    cols: PosInt
    pitch_m: Positive
    focal_length_m: Positive
    aperture: Literal["cell", "round"]
    offset_m: Vec2
    rotation_deg: Finite
    tilt_deg: Vec2


class PoseEntry(_Model):
    """``pose``: the model frame's pose in the world. Further keys that the pose writer
    (:meth:`lftransfer.calibration.pose.ArrayPose.to_json`) produces are accepted and dropped (measurements for
    reports); any other key is refused."""

    tilt_deg: Vec2
    rotation_deg: Finite
    offset_mm: Vec2
    scale: Positive
    rms_px: Diagnostic = None
    pnp_rms_px: Diagnostic = None
    residual_mm: Diagnostic = None

    @model_validator(mode="before")
    @classmethod
    def _drop_writer_extras(cls, data: Any) -> Any:
        if isinstance(data, dict):
            extras = _pose_writer_keys() - set(cls.model_fields)
            data = {k: v for k, v in data.items() if k not in extras}
        return data


def _pose_writer_keys() -> set[str]:
    """Keys that :meth:`lftransfer.calibration.pose.ArrayPose.to_json` writes."""
    try:
        from lftransfer.calibration.pose import ArrayPose

        return set(ArrayPose(tilt=(0.0, 0.0), rotation=0.0, offset=(0.0, 0.0), scale=1.0).to_json())
    except Exception:  # noqa: BLE001 - a changed constructor: the declared fields only
        return set(PoseEntry.model_fields)


class LensletCameraEntry(_Model):
    """One lenslet's OpenCV camera: ``camera_matrix`` (3 x 3) and ``dist_coeffs`` (k1 k2 p1 p2 k3 ...)."""

    camera_matrix: Matrix3
    dist_coeffs: Annotated[list[Finite], Field(min_length=2, max_length=14)]


class DeviceEntry(_Model):
    """``lf_camera`` or ``projector``: size, bit depth, focal-plane homography, one camera per lenslet."""

    width: PosInt
    height: PosInt
    bits: Annotated[int, Strict(), Field(ge=1, le=16)]
    homography: Matrix3
    lenslets: Annotated[list[LensletCameraEntry], Field(min_length=1)]

    @field_validator("homography")
    @classmethod
    def _homography_invertible(cls, m: list[list[float]]) -> list[list[float]]:
        return _invertible(m)


class VignettingEntry(_Model):
    """``radiometry.vignetting``: polynomial degree, its coefficients, the camera image's [H, W], the floor."""

    degree: Annotated[int, Strict(), Field(ge=0, le=12)]
    coeffs: list[Finite]
    shape: Annotated[list[PosInt], Field(min_length=2, max_length=2)]
    floor: Annotated[float, Strict(), Field(ge=0, le=1)] = 0.05

    @model_validator(mode="after")
    def _coefficient_count(self) -> "VignettingEntry":
        want = (self.degree + 1) * (self.degree + 2) // 2
        if len(self.coeffs) != want:
            raise ValueError(f"coeffs: a degree-{self.degree} polynomial has {want} coefficients, "
                             f"found {len(self.coeffs)}")
        return self


class RadiometryEntry(_Model):
    """``radiometry``: responses, exposure, vignetting, cross-talk, black level, brightness; ``diagnostics`` is
    free-form (measurements for the report)."""

    camera_gamma: PosVec3
    camera_exposure: Positive
    vignetting: VignettingEntry
    projector_gamma: PosVec3
    cross_talk: Matrix3
    black_level: Annotated[list[NonNegative], Field(min_length=3, max_length=3)]
    max_radiance: Positive
    diagnostics: dict[str, Any] = Field(default_factory=dict)


class LensletCentresEntry(_Model):
    """``lenslet_centres`` (optional): the spots found, LF camera pixels, and their lattice indices."""

    centres_px: list[Vec2]
    indices: list[Annotated[list[NonNegInt], Field(min_length=2, max_length=2)]]
    rms_px: Diagnostic = None
    pitch_px: Diagnostic = None
    rotation_deg: Diagnostic = None


class DistortionEntry(_Model):
    """``distortion`` (optional): the collimator mount's angle and the fit's residual."""

    mount_angle_deg: Diagnostic = None
    rms: Diagnostic = None


class ProjectorMappingEntry(_Model):
    """``projector_mapping`` (optional): LF camera -> projector pixel homography and its fit."""

    camera_to_projector: Matrix3
    rms_px: Diagnostic = None
    pixels: Optional[NonNegInt] = None

    @field_validator("camera_to_projector")
    @classmethod
    def _mapping_invertible(cls, m: list[list[float]]) -> list[list[float]]:
        return _invertible(m)


class LightEntry(_Model):
    """``light`` (optional; files from before the point light step lack it): the real point light as measured,
    world frame (the scene file's), metres; the rest are the fit's measurements, for reports. A scene with several
    point lights has ``lights`` instead: one entry per light, in the scene file's order."""

    position_m: Vec3
    start_m: Optional[Vec3] = None
    intensity_albedo: Optional[Annotated[list[NonNegative], Field(min_length=3, max_length=3)]] = None
    dark_ratio: Diagnostic = None
    residual_rms: Diagnostic = None
    std_mm: Optional[Annotated[list[Diagnostic], Field(min_length=3, max_length=3)]] = None
    pixels: Optional[NonNegInt] = None
    boards: Optional[NonNegInt] = None


class CalibrationFile(_Model):
    """A whole calibration file."""

    format: Literal["lftransfer-calibration/1"]
    lens_array: LensArrayEntry
    pose: PoseEntry
    lf_camera: DeviceEntry
    projector: DeviceEntry
    radiometry: RadiometryEntry
    lenslet_centres: Optional[LensletCentresEntry] = None
    distortion: Optional[DistortionEntry] = None
    projector_mapping: Optional[ProjectorMappingEntry] = None
    light: Optional[LightEntry] = None
    lights: Optional[Annotated[list[LightEntry], Field(min_length=2)]] = None

    @model_validator(mode="after")
    def _one_light_section(self):
        if self.light is not None and self.lights is not None:
            raise ValueError("give light (one point light) or lights (several), not both")
        return self

    def light_entries(self) -> list[LightEntry]:
        """The measured point lights, in the scene file's order (none: a file from before the step)."""
        return [self.light] if self.light is not None else list(self.lights or [])


def parse_calibration_file(data: object, name: str) -> CalibrationFile:
    """Validate a calibration file's JSON value.

    Args:
        data: the parsed JSON.
        name: how messages name the file.

    Returns:
        CalibrationFile.

    Raises:
        CalibrationFileError: not a JSON object, another format, or invalid fields (one line naming ``name`` and
            the field path).
    """
    if not isinstance(data, dict):
        raise CalibrationFileError(f"{name}: <calibration>: expected a JSON object (a calibration file from lft "
                                   f"calibrate), found {type(data).__name__}")
    if data.get("format") != FORMAT:
        raise CalibrationFileError(f"{name}: format: expected {FORMAT!r} (a calibration file from lft calibrate), "
                                   f"found {data.get('format')!r}")
    try:
        return CalibrationFile.model_validate(data)
    except ValidationError as exc:
        raise CalibrationFileError(validation_message(name, exc, root="<calibration>", first_per_field=True,
                                                      model=CalibrationFile, data=data)) from None
