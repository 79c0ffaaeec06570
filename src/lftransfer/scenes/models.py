"""The tables of a scene file as pydantic models: field types, the rig's nominal values (``[rig]``), the view
camera (``[view]``), point lights (``[light]``), render settings (``[render]``), materials, the time line
(``[animation]``) and the measured effect (``[effect]``).

Objects are in :mod:`lftransfer.scenes.objects`, whole scenes in :mod:`lftransfer.scenes.scene`. Units are
metres, degrees and linear RGB (``docs/scene-format.md``). The render settings' choices and defaults are
:mod:`lftransfer.choices`'s.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal, Union

import numpy as np
from pydantic import BaseModel, ConfigDict, Discriminator, Field, Tag, ValidationInfo, field_validator

from lftransfer.choices import (
    DEFAULT_ANGULAR_SAMPLES,
    DEFAULT_APERTURE_SAMPLES,
    DEFAULT_COMPOSITE,
    DEFAULT_GT_SPP,
    DEFAULT_LIGHTING_MODEL,
    DEFAULT_MAX_DEPTH,
    DEFAULT_PROJECTION,
    DEFAULT_RECONSTRUCTION,
    DEFAULT_SPP,
    DEFAULT_WINDOW,
    Composite,
    LightingModel,
    Projection,
    Reconstruction,
    Window,
)
from lftransfer.scenes.animation import frame_times
from lftransfer.scenes.assets import _scene_file, _texture_file
from lftransfer.validation import STRICT_NUMBER

__all__ = [
    "Float",
    "PosFloat",
    "NonNegFloat",
    "Unit",
    "PosInt",
    "Vec3",
    "PosVec3",
    "NonNegVec3",
    "RGBUnit",
    "Size2",
    "RigConfig",
    "InterfaceConfig",
    "MAX_INTERFACES",
    "ViewConfig",
    "MAX_LIGHTS",
    "LightConfig",
    "RenderConfig",
    "DiffuseMaterial",
    "GlossyMaterial",
    "MetalMaterial",
    "EmitterMaterial",
    "Material",
    "AnimationConfig",
    "EffectConfig",
]


# --------------------------------------------------------------------------------------------------------------
# Field types

_Num = STRICT_NUMBER
Float = Annotated[float, _Num, Field(allow_inf_nan=False)]
PosFloat = Annotated[float, _Num, Field(gt=0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, _Num, Field(ge=0, allow_inf_nan=False)]
Unit = Annotated[float, _Num, Field(ge=0, le=1, allow_inf_nan=False)]
PosInt = Annotated[int, _Num, Field(gt=0)]
Vec3 = Annotated[list[Float], Field(min_length=3, max_length=3)]
PosVec3 = Annotated[list[PosFloat], Field(min_length=3, max_length=3)]
NonNegVec3 = Annotated[list[NonNegFloat], Field(min_length=3, max_length=3)]
RGBUnit = Annotated[list[Unit], Field(min_length=3, max_length=3)]
Size2 = Annotated[list[PosInt], Field(min_length=2, max_length=2)]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=False)


# --------------------------------------------------------------------------------------------------------------
# Hardware, camera, light, render settings

class RigConfig(_Model):
    """Nominal values of the light field interface hardware (lens array, LF camera, projector).

    Attributes:
        lattice: lens lattice, ``"hex"`` or ``"rect"``.
        rows, cols: number of lenslets.
        pitch_mm: lens pitch, millimetres.
        focal_mm: lenslet focal length, millimetres.
        aperture: ``"cell"`` (apertures tile the lattice cells) or ``"round"`` (disks of diameter pitch).
        lf_camera, projector: [width, height] in pixels.
        angular_samples: U = V of the light field grid.
        lf_camera_bits, projector_bits: bit depth of the device codes.
        camera_gamma: per-channel camera response, code = signal^(1/gamma).
        projector_gamma: per-channel projector response, radiance = code^gamma.
        exposure: normalised camera signal per unit radiance (per W m^-2 sr^-1).
        projector_max_radiance: radiance of a full-code projector pixel, W m^-2 sr^-1.
        read_noise: standard deviation of the read noise, fraction of full scale.
        full_well: electrons at full scale (sets the shot noise).
        seed: seed of the simulated noise.
    """

    lattice: Literal["hex", "rect"] = "hex"
    rows: PosInt = 10
    cols: PosInt = 12
    pitch_mm: PosFloat = 25.4
    focal_mm: PosFloat = 25.4
    aperture: Literal["cell", "round"] = "cell"
    lf_camera: Size2 = Field(default_factory=lambda: [2048, 1536])
    projector: Size2 = Field(default_factory=lambda: [1024, 768])
    angular_samples: PosInt = DEFAULT_ANGULAR_SAMPLES
    lf_camera_bits: Annotated[int, _Num, Field(ge=1, le=16)] = 12
    projector_bits: Annotated[int, _Num, Field(ge=1, le=16)] = 8
    camera_gamma: PosVec3 = Field(default_factory=lambda: [1.0, 1.0, 1.0])
    projector_gamma: PosVec3 = Field(default_factory=lambda: [2.2, 2.2, 2.2])
    exposure: PosFloat = 0.25
    projector_max_radiance: PosFloat = 8.0
    read_noise: NonNegFloat = 0.001
    full_well: PosFloat = 20000.0
    seed: Annotated[int, _Num, Field(ge=0)] = 0

    @property
    def pitch(self) -> float:
        """Lens pitch in metres."""
        return self.pitch_mm * 1e-3

    @property
    def focal_length(self) -> float:
        """Lenslet focal length in metres."""
        return self.focal_mm * 1e-3


MAX_INTERFACES = 6            # light field interfaces a scene may give (six planes bound a box)


class InterfaceConfig(_Model):
    """One light field interface of several (``[[interface]]``): a lens array with its LF camera and projector, as
    ``[rig]`` describes them, standing at a pose in the world (docs/architecture.md, "Several interfaces").

    The interface's own frame has its array in the plane z = 0 and its real side at z > 0, as the one interface of
    a ``[rig]`` scene has in the world. The real objects stand on the real side of every interface; each synthetic
    object on the synthetic side of at least one.

    Attributes:
        name: a label (reports, the page).
        translate: where the interface's frame origin (the middle of its lattice) stands, world metres.
        rotate_deg: its frame's rotation into the world (about x, then y, then z, degrees): the array's normal,
            pointing at the real objects, is the rotated +z.
        rows, cols: this array's lenslets (default: ``[rig]``'s); every other device and optical value is
            ``[rig]``'s.
    """

    name: Annotated[str, Field(min_length=1)]
    translate: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    rotate_deg: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    rows: PosInt | None = None
    cols: PosInt | None = None

    def to_world(self) -> np.ndarray:
        """(4, 4) float64 rigid transform: a point of the interface's frame -> the world."""
        from lftransfer.optics.geometry import rotation_matrix

        m = np.eye(4)
        m[:3, :3] = rotation_matrix(self.rotate_deg)
        m[:3, 3] = self.translate
        return m

    @property
    def at_origin(self) -> bool:
        """Whether the interface's frame is the world's (no translation, no rotation)."""
        return not any(self.translate) and not any(self.rotate_deg)

    def rig(self, shared: RigConfig) -> RigConfig:
        """This interface's hardware: ``shared`` (the scene's ``[rig]``) with its own lenslet counts."""
        update = {k: getattr(self, k) for k in ("rows", "cols") if getattr(self, k) is not None}
        return shared.model_copy(update=update) if update else shared


class ViewConfig(_Model):
    """The view camera, a pinhole that sees both half-spaces.

    Attributes:
        resolution: [width, height] in pixels.
        origin, target: camera position and the point it looks at, metres.
        up: up vector (need not be unit length, must not be parallel to the viewing direction).
        fov_deg: horizontal field of view, degrees, in (0, 180).
    """

    resolution: Size2 = Field(default_factory=lambda: [1024, 768])
    origin: Vec3 = Field(default_factory=lambda: [0.55, 0.22, 0.0])
    target: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    up: Vec3 = Field(default_factory=lambda: [0.0, 1.0, 0.0])
    fov_deg: Annotated[float, _Num, Field(gt=0, lt=180)] = 35.0

    @field_validator("target")
    @classmethod
    def _target_differs(cls, target: list[float], info: ValidationInfo) -> list[float]:
        origin = info.data.get("origin")
        if origin is not None and np.allclose(origin, target, rtol=0, atol=1e-12):
            raise ValueError(f"target must differ from origin, found both {target}")
        return target

    @field_validator("up")
    @classmethod
    def _up_not_parallel(cls, up: list[float], info: ValidationInfo) -> list[float]:
        origin, target = info.data.get("origin"), info.data.get("target")
        u = np.asarray(up, float)
        if np.linalg.norm(u) == 0:
            raise ValueError("up must be a non-zero vector, found [0, 0, 0]")
        if origin is not None and target is not None:
            d = np.asarray(target, float) - np.asarray(origin, float)
            if np.linalg.norm(np.cross(d / np.linalg.norm(d), u / np.linalg.norm(u))) < 1e-6:
                raise ValueError(f"up must not be parallel to the viewing direction {d.tolist()}, found {up}")
        return up


MAX_LIGHTS = 8      # real point lights a scene may have (each is measured by its own calibration step)


class LightConfig(_Model):
    """A point light. It is real (the simulated rig has it) and the renderer uses a virtual twin of it.

    Attributes:
        position: metres.
        intensity: radiant intensity per RGB channel, W/sr.
    """

    kind: Literal["point"] = "point"
    position: Vec3
    intensity: NonNegVec3 = Field(default_factory=lambda: [1.0, 1.0, 1.0])


class ProbeConfig(_Model):
    """The direct light as a light probe (``[light]`` with ``kind = "probe"``, docs/scene-format.md): the real
    objects stand in a lit room (``[environment]``, known to the simulated rig only), a mirror ball on a mount at a
    measured place is photographed by the view camera, and the environment it shows lights the synthetic objects.

    Attributes:
        kind: ``"probe"``.
        ball_centre: where the ball's mount holds it, world metres (measured once; real half-space, seen by the
            view camera).
        ball_radius: metres.
        ball_reflectance: its mirror reflectance per channel (a chrome ball: about 0.6 to 0.9).
        map_width: texels of the recovered map around (its height is half).
    """

    kind: Literal["probe"]
    ball_centre: Vec3
    ball_radius: PosFloat = 0.025
    ball_reflectance: RGBUnit = Field(default_factory=lambda: [1.0, 1.0, 1.0])
    map_width: Annotated[int, Field(ge=16, le=1024, multiple_of=2)] = 128

    @field_validator("ball_centre")
    @classmethod
    def _real_side(cls, value):
        if value[2] <= 0:
            raise ValueError(f"the ball stands among the real objects (z > 0), found z = {value[2]}")
        return value


def _read_map(path: Path) -> np.ndarray:
    """(H, W, 3) float32 linear RGB of an equirectangular map file (read by Mitsuba); a ValueError unless it is
    twice as wide as high with three channels or more."""
    from lftransfer.backend import mitsuba

    rgb = np.array(mitsuba().Bitmap(str(path)), np.float32)
    if rgb.ndim != 3 or rgb.shape[2] < 3 or rgb.shape[1] != 2 * rgb.shape[0]:
        raise ValueError(f"expected an RGB map twice as wide as high, found shape {rgb.shape}")
    return np.ascontiguousarray(rgb[..., :3])


class EnvironmentConfig(_Model):
    """The light of the room around the real objects (``[environment]``): a sky, a ground and a sun, or an HDR
    map from a file. Like the real objects it is known to the simulated rig and its ground truth only; the
    pipeline measures it with the light probe.

    Attributes:
        file: an equirectangular HDR map (EXR, linear radiance, Mitsuba's ``envmap`` convention: +y up), relative
            to the scene file; when given, the sky fields are not used.
        zenith, horizon, ground: radiance of the sky straight up, of the sky at the horizon (blended with the
            sine of the elevation) and of everything below the horizon, W m^-2 sr^-1.
        sun_direction: towards the sun, world (normalised when read).
        sun_radiance: the sun's peak radiance, W m^-2 sr^-1 (its disc falls off as
            ``exp(-(1 - cos angle) / (1 - cos sun_size_deg))``).
        sun_size_deg: the sun's angular radius.
        width: texels of the map around (its height is half).
    """

    file: Path | None = None
    zenith: NonNegVec3 = Field(default_factory=lambda: [0.55, 0.7, 1.0])
    horizon: NonNegVec3 = Field(default_factory=lambda: [0.9, 0.9, 0.85])
    ground: NonNegVec3 = Field(default_factory=lambda: [0.25, 0.2, 0.15])
    sun_direction: Vec3 = Field(default_factory=lambda: [0.75, 0.645, 0.16])
    sun_radiance: NonNegVec3 = Field(default_factory=lambda: [2600.0, 2450.0, 2200.0])
    sun_size_deg: Annotated[float, _Num, Field(gt=0, le=45, allow_inf_nan=False)] = 2.5
    width: Annotated[int, Field(ge=16, le=4096, multiple_of=2)] = 256

    @field_validator("file", mode="plain")
    @classmethod
    def _map_file(cls, value: Any, info: ValidationInfo) -> Path | None:
        if value is None:
            return None
        if not isinstance(value, (str, Path)):
            raise ValueError(f"expected an EXR file path string, found {type(value).__name__} {value!r}")
        return _scene_file(value, info, "environment map file", _read_map, "cannot read an equirectangular map from")

    @field_validator("sun_direction")
    @classmethod
    def _not_zero(cls, value):
        if np.linalg.norm(value) < 1e-9:
            raise ValueError("sun_direction must not be the zero vector")
        return value

    def radiance_map(self) -> np.ndarray:
        """(H, W, 3) float32 radiance of the room's light, equirectangular (Mitsuba's ``envmap`` convention,
        :func:`lftransfer.optics.geometry.env_directions`), world frame."""
        if self.file is not None:
            return _read_map(self.file)
        from lftransfer.optics.geometry import env_directions

        d = env_directions(self.width, self.width // 2)
        up = np.clip(d[..., 1:2], 0.0, 1.0)
        sky = (1 - up) * np.asarray(self.horizon) + up * np.asarray(self.zenith)
        rgb = np.where(d[..., 1:2] > 0, sky, np.asarray(self.ground))
        s = np.asarray(self.sun_direction, float) / np.linalg.norm(self.sun_direction)
        lobe = np.exp(-(1 - d @ s) / (1 - np.cos(np.radians(self.sun_size_deg))))
        return (rgb + lobe[..., None] * np.asarray(self.sun_radiance)).astype(np.float32)


class RenderConfig(_Model):
    """Render settings.

    Attributes:
        lighting_model: how the incident light field lights the synthetic scene: ``"area"`` (lenslet apertures
            sampled), ``"point"`` (the paper's projective point lights) or ``"prefiltered"``.
        aperture_samples: area model: samples per lenslet aperture.
        reconstruction: area model: how the captured light field is read between lenslet centres, ``"linear"``
            (blended across the three lenslets around each aperture point, continuous in position) or ``"box"``
            (one sample per lenslet over its whole aperture).
        projection: area model: what the projector is sent, ``"depth"`` (the projected light field prefiltered
            from the real scene's depth, measured through the rig with one extra frame, so that each real point
            receives the synthetic light of the rays that land on it) or ``"box"`` (each entry the mean of the
            synthetic light over its lenslet's aperture).
        window: area model: what the synthetic scene receives from beyond the lenslets' window (light steeper than
            about 26.6 degrees, which no lenslet records), ``"edge"`` (the captured light field read at the
            window's edge: diffuse real surfaces look much the same from there) or ``"cut"`` (nothing).
        composite: how the final frame is put together, ``"over"`` (the synthetic render over the real view) or
            ``"depth"`` (the nearer surface per pixel, the real scene's depth measured through the rig).
        spp: samples per pixel of view renders and per light field sample.
        lf_spp: rays per entry of the outgoing light field render (points over the entry's lenslet aperture), which
            the depth prefilter also uses to model where each entry's light lands; None: ``spp``. More rays let the
            prefilter sharpen edges finer than a lenslet (Fig. 5's penumbra:
            benchmarks/reconstruction/projector_prefilter.py).
        max_depth: path depth (surface interactions) inside each half-space.
        gt_spp: samples per pixel of the path-traced ground truth.
    """

    lighting_model: LightingModel = DEFAULT_LIGHTING_MODEL
    aperture_samples: PosInt = DEFAULT_APERTURE_SAMPLES
    reconstruction: Reconstruction = DEFAULT_RECONSTRUCTION
    projection: Projection = DEFAULT_PROJECTION
    window: Window = DEFAULT_WINDOW
    composite: Composite = DEFAULT_COMPOSITE
    spp: PosInt = DEFAULT_SPP
    lf_spp: PosInt | None = None
    max_depth: PosInt = DEFAULT_MAX_DEPTH
    gt_spp: PosInt = DEFAULT_GT_SPP


# --------------------------------------------------------------------------------------------------------------
# Materials

class DiffuseMaterial(_Model):
    """Lambertian reflector.

    Attributes:
        albedo: diffuse reflectance per RGB channel, in [0, 1].
        texture: optional image file (relative to the scene file; stored absolute) whose linear colours multiply
            ``albedo`` across the surface, mapped by the shape's texture coordinates (docs/scene-format.md).
    """

    type: Literal["diffuse"] = "diffuse"
    albedo: RGBUnit = Field(default_factory=lambda: [0.5, 0.5, 0.5])
    texture: Path | None = None

    @field_validator("texture", mode="plain")
    @classmethod
    def _texture(cls, value: Any, info: ValidationInfo) -> Path | None:
        return _texture_file(value, info)


class GlossyMaterial(_Model):
    """Diffuse base under a rough dielectric coating (Mitsuba ``roughplastic``, GGX, IOR 1.49).

    Attributes:
        albedo: diffuse reflectance of the base, in [0, 1].
        specular: multiplier of the coating's Fresnel reflection, in [0, 1].
        roughness: GGX alpha in [0, 1]; 0 is a smooth coating.
        texture: optional image file whose linear colours multiply ``albedo`` (as for a diffuse material).
    """

    type: Literal["glossy"] = "glossy"
    albedo: RGBUnit = Field(default_factory=lambda: [0.5, 0.5, 0.5])
    specular: RGBUnit = Field(default_factory=lambda: [1.0, 1.0, 1.0])
    roughness: Unit = 0.1
    texture: Path | None = None

    @field_validator("texture", mode="plain")
    @classmethod
    def _texture(cls, value: Any, info: ValidationInfo) -> Path | None:
        return _texture_file(value, info)


class MetalMaterial(_Model):
    """Rough conductor with a given reflectance (Mitsuba ``roughconductor``, material ``none``, GGX).

    Attributes:
        specular: reflectance per RGB channel, in [0, 1].
        roughness: GGX alpha in [0, 1]; 0 is a mirror.
    """

    type: Literal["metal"] = "metal"
    specular: RGBUnit = Field(default_factory=lambda: [0.9, 0.9, 0.9])
    roughness: Unit = 0.1


class EmitterMaterial(_Model):
    """A diffuse emitter that reflects nothing (a Mitsuba ``area`` emitter on a black surface), e.g. the sun of
    the paper's Fig. 5: synthetic objects only (the real side's light is ``[light]``). It lights the synthetic
    objects directly and the real ones through the projector.

    Attributes:
        radiance: emitted radiance per RGB channel, W m^-2 sr^-1, the same in every direction of its front side.
    """

    type: Literal["emitter"] = "emitter"
    radiance: NonNegVec3 = Field(default_factory=lambda: [1.0, 1.0, 1.0])


def _material_tag(value: Any) -> str | None:
    """The material's ``type``; a table without one is diffuse."""
    tag = value.get("type", "diffuse") if isinstance(value, dict) else getattr(value, "type", None)
    return tag if isinstance(tag, str) else None


Material = Annotated[
    Union[Annotated[DiffuseMaterial, Tag("diffuse")], Annotated[GlossyMaterial, Tag("glossy")],
          Annotated[MetalMaterial, Tag("metal")], Annotated[EmitterMaterial, Tag("emitter")]],
    Discriminator(_material_tag, custom_error_type="material_type",
                  custom_error_message="a material table needs type = 'diffuse', 'glossy', 'metal' or 'emitter'"),
]
_MATERIAL_TAGS = {"diffuse", "glossy", "metal", "emitter"}


# --------------------------------------------------------------------------------------------------------------
# Time line and effect

class AnimationConfig(_Model):
    """The time line of an animated scene (``[animation]``).

    Attributes:
        duration_s: length of the sequence, seconds.
        fps: frames per second of rendered sequences.
    """

    duration_s: PosFloat
    fps: PosFloat = 24.0

    def frame_times(self) -> np.ndarray:
        """(F,) float64 times of the frames, seconds: ``i / fps`` below ``duration_s``."""
        return frame_times(self.duration_s, self.fps)


class EffectConfig(_Model):
    """The effect a scene shows, measured per verified frame against the ground truth (``[effect]``,
    docs/scene-format.md): the light that a moving synthetic object ``by`` adds to, or takes from, a real object
    ``on``, seen by the view camera, against the distance between the two.

    Attributes:
        kind: ``"shadow"``: the shadow ``by`` casts on ``on`` (its contrast and penumbra width, Fig. 5) |
            ``"reflection"``: the light of ``by`` that ``on`` reflects (the mean radiance it adds, Fig. 6).
        on: name of the real object measured.
        by: name of the synthetic object whose effect it is (usually a keyframed one).
    """

    kind: Literal["shadow", "reflection"]
    on: str
    by: str
