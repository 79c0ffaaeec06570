"""The scene file format: pydantic models of a TOML scene and its loader.

A scene file describes the light field interface hardware (``[rig]``), the view camera (``[view]``), the real
point lights (``[light]``, or several ``[[light]]``), render settings (``[render]``) and the objects of the two
half-spaces (``[[real]]`` at z > 0, known only to the simulated rig; ``[[synthetic]]`` at z < 0, rendered). Units
are metres, degrees and linear RGB. ``docs/scene-format.md`` is the reference of every field.

This module does not import Mitsuba: :mod:`lftransfer.render.shapes` turns the validated objects into
Mitsuba scene dicts.
"""

from __future__ import annotations

import functools
import math
import numbers
import re
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import numpy as np
from pydantic import (
    AfterValidator,
    AliasChoices,
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    ValidationError,
    Tag,
    ValidationInfo,
    field_validator,
    model_validator,
)

from lftransfer.scenes.animation import Interpolation, frame_times, interpolate

from lftransfer.validation import STRICT_NUMBER, read_toml, validation_message

__all__ = [
    "SceneError",
    "RigConfig",
    "ViewConfig",
    "LightConfig",
    "EffectConfig",
    "RenderConfig",
    "DiffuseMaterial",
    "GlossyMaterial",
    "MetalMaterial",
    "EmitterMaterial",
    "Material",
    "ObjectConfig",
    "Keyframe",
    "AnimationConfig",
    "SceneConfig",
    "load_scene",
    "builtin_scene",
    "builtin_scenes",
    "with_overrides",
    "read_mesh",
    "read_texture",
    "TEXTURED_SHAPES",
]


class SceneError(ValueError):
    """An invalid scene file.

    The message reads ``"<file>: <field path>: <what was expected, what was found>"``, e.g.
    ``"fig4.toml: real[0].material.roughness: Input should be less than or equal to 1, found 1.5"``.
    """


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
    angular_samples: PosInt = 48
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

    position: Vec3
    intensity: NonNegVec3 = Field(default_factory=lambda: [1.0, 1.0, 1.0])


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
        spp: samples per pixel of view renders and per light field sample.
        lf_spp: rays per entry of the outgoing light field render (points over the entry's lenslet aperture), which
            the depth prefilter also uses to model where each entry's light lands; None: ``spp``. More rays let the
            prefilter sharpen edges finer than a lenslet (Fig. 5's penumbra, docs/architecture.md).
        max_depth: path depth (surface interactions) inside each half-space.
        gt_spp: samples per pixel of the path-traced ground truth.
    """

    lighting_model: Literal["area", "point", "prefiltered"] = "area"
    aperture_samples: PosInt = 4
    reconstruction: Literal["box", "linear"] = "linear"
    projection: Literal["box", "depth"] = "depth"
    window: Literal["edge", "cut"] = "edge"
    spp: PosInt = 4
    lf_spp: PosInt | None = None
    max_depth: PosInt = 3
    gt_spp: PosInt = 2048


# --------------------------------------------------------------------------------------------------------------
# Materials

def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


@functools.lru_cache(maxsize=16)
def _read_texture(path: str, mtime_ns: int, size: int) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as image:
        image.load()
        rgb = np.asarray(image.convert("RGB"), dtype=np.float64) / 255.0
    if rgb.ndim != 3 or rgb.shape[0] < 1 or rgb.shape[1] < 1:
        raise ValueError("the file holds no pixels")
    data = _srgb_to_linear(rgb).astype(np.float32)
    data.setflags(write=False)
    return data


def read_texture(path: str | Path) -> np.ndarray:
    """Linear RGB colours of an image file (PNG, JPEG, BMP, TIFF, ...: what Pillow reads), cached by path, size
    and modification time.

    The file's values are taken as 8-bit sRGB-encoded colours (any alpha channel is ignored) and decoded with the
    sRGB curve.

    Args:
        path: the file.

    Returns:
        (H, W, 3) float32 in [0, 1], row 0 the top of the image; read-only.
    """
    st = Path(path).stat()
    return _read_texture(str(Path(path).resolve()), st.st_mtime_ns, st.st_size)


def _scene_file(value: Any, info: ValidationInfo, what: str, read, cannot: str) -> Path:
    """A file a scene names (a mesh, a texture): relative to the scene file's folder, resolved, existing and
    readable by ``read``; stored absolute. ``what`` and ``cannot`` word the errors."""
    path = Path(value).expanduser()
    if not path.is_absolute():
        base = (info.context or {}).get("base_dir")
        path = Path(base) / path if base is not None else path
    path = path.resolve()
    if not path.is_file():
        raise ValueError(f"{what} does not exist: {path}")
    try:
        read(path)
    except Exception as exc:  # noqa: BLE001 - any reader failure is a bad file
        raise ValueError(f"{cannot} {path}: {exc}") from None
    return path


def _texture_file(value: Any, info: ValidationInfo) -> Path | None:
    """A material's ``texture``: an existing, readable image, relative to the scene file; stored absolute."""
    if value is None:
        return None
    if not isinstance(value, (str, Path)):
        raise ValueError(f"expected an image file path string, found {type(value).__name__} {value!r}")
    return _scene_file(value, info, "texture file", read_texture, "cannot read an image from texture file")


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
# Objects

ShapeName = Literal["sphere", "box", "rectangle", "cylinder", "mesh"]
_SIZE_COMPONENTS = {"box": 3, "rectangle": 2}
_NEEDS = {"sphere": {"radius"}, "box": {"size"}, "rectangle": {"size"}, "cylinder": {"radius", "height"},
          "mesh": {"file"}}
CYLINDER_SECTIONS = 64          # facets around a cylinder's triangle mesh
TEXTURED_SHAPES = ("rectangle", "box", "sphere")   # shapes with texture coordinates (docs/scene-format.md)


@functools.lru_cache(maxsize=32)
def _read_mesh(path: str, mtime_ns: int, size: int) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    mesh = trimesh.load(path, force="mesh")
    vertices = np.array(mesh.vertices, dtype=np.float64)
    faces = np.array(mesh.faces, dtype=np.int64)
    if faces.ndim != 2 or len(faces) == 0:
        raise ValueError("the file holds no triangles")
    vertices.setflags(write=False)
    faces.setflags(write=False)
    return vertices, faces


def read_mesh(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of a mesh file (OBJ, PLY, STL, ...), cached by path, size and modification time.

    Args:
        path: the file.

    Returns:
        vertices (N, 3) float64 in the file's units (metres) and faces (F, 3) int64; read-only arrays.
    """
    st = Path(path).stat()
    return _read_mesh(str(Path(path).resolve()), st.st_mtime_ns, st.st_size)


def _rotation(rotate_deg) -> np.ndarray:
    """R = Rz @ Ry @ Rx: rotations about the world x, then y, then z axes (degrees)."""
    ax, ay, az = np.radians(np.asarray(rotate_deg, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _positive_scale(value: Any) -> float | list[float]:
    """A uniform scale factor or three, each a positive finite number."""
    def positive(x: Any) -> float:
        if isinstance(x, (str, bool)) or not isinstance(x, numbers.Real):
            raise ValueError(f"scale must be a number or 3 numbers, found {type(x).__name__} {x!r}")
        if not math.isfinite(float(x)) or float(x) <= 0:
            raise ValueError(f"scale must be positive, found {x!r}")
        return float(x)

    if isinstance(value, (list, tuple, np.ndarray)):
        if len(value) != 3:
            raise ValueError(f"scale needs 1 or 3 components, found {len(value)}: {list(value)}")
        return [positive(x) for x in value]
    return positive(value)


class Keyframe(_Model):
    """An object's pose at one moment of an animated scene; a field left out is the object's own value there.

    Attributes:
        time_s: seconds from the start of the sequence, in [0, animation.duration_s].
        translate: metres.
        rotate_deg: Euler angles about x, then y, then z (world axes), degrees.
        scale: uniform factor or [sx, sy, sz].
    """

    time_s: NonNegFloat
    translate: Vec3 | None = None
    rotate_deg: Vec3 | None = None
    scale: Union[float, list[float], None] = None

    @field_validator("scale", mode="plain")
    @classmethod
    def _scale(cls, value: Any) -> float | list[float] | None:
        return None if value is None else _positive_scale(value)


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


class ObjectConfig(_Model):
    """One object of a half-space: a primitive or a mesh, a transform and a material.

    The object's local geometry (centred at its local origin) is scaled by ``scale``, rotated about the world
    x, then y, then z axes by ``rotate_deg`` and translated by ``translate``.

    Attributes:
        name: a label; Mitsuba shape ids are derived from it (see :mod:`lftransfer.render.shapes`).
        shape: ``"sphere"``, ``"box"``, ``"rectangle"``, ``"cylinder"`` or ``"mesh"``.
        size: box: full edge lengths [sx, sy, sz]; rectangle: [sx, sy] (in its local xy plane, normal +z);
            metres.
        radius: sphere and cylinder radius, metres.
        height: cylinder height along its local z axis (capped, centred at the origin), metres.
        file: mesh file (OBJ/PLY/STL); relative paths are relative to the scene file; stored absolute.
        translate: metres.
        rotate_deg: Euler angles about x, then y, then z (world axes), degrees.
        scale: uniform factor or [sx, sy, sz], applied first.
        material: diffuse, glossy or metal (chosen by its ``type``).
        keyframes: poses at increasing times of the scene's ``[animation]`` (``[[real.keyframes]]``,
            ``[[synthetic.keyframes]]``); empty: the object stands still.
        interpolation: how the pose goes from key to key, ``"linear"`` or ``"smooth"``
            (:mod:`lftransfer.scenes.animation`).
    """

    name: Annotated[str, Field(min_length=1)]
    shape: ShapeName
    size: list[PosFloat] | None = Field(default=None, validate_default=True)
    radius: PosFloat | None = Field(default=None, validate_default=True)
    height: PosFloat | None = Field(default=None, validate_default=True)
    file: Path | None = Field(default=None, validate_default=True)
    translate: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    rotate_deg: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    scale: Union[float, list[float]] = 1.0
    material: Material = Field(default_factory=DiffuseMaterial)
    keyframes: list[Keyframe] = Field(default_factory=list)
    interpolation: Interpolation = "linear"

    # --- validation -------------------------------------------------------------------------------------------
    @staticmethod
    def _check_presence(field: str, value: Any, info: ValidationInfo) -> None:
        shape = info.data.get("shape")
        if shape is None:
            return
        if field in _NEEDS[shape] and value is None:
            raise ValueError(f"a {shape} needs '{field}', found none")
        if field not in _NEEDS[shape] and value is not None:
            raise ValueError(f"'{field}' does not apply to a {shape} (it takes {sorted(_NEEDS[shape])}), "
                             f"found {value!r}")

    @field_validator("size")
    @classmethod
    def _size(cls, value: list[float] | None, info: ValidationInfo) -> list[float] | None:
        cls._check_presence("size", value, info)
        shape = info.data.get("shape")
        if value is not None and shape in _SIZE_COMPONENTS and len(value) != _SIZE_COMPONENTS[shape]:
            raise ValueError(f"a {shape} size has {_SIZE_COMPONENTS[shape]} components, found {len(value)}: {value}")
        return value

    @field_validator("radius", "height")
    @classmethod
    def _radius_height(cls, value: float | None, info: ValidationInfo) -> float | None:
        cls._check_presence(info.field_name, value, info)
        return value

    @field_validator("file", mode="plain")
    @classmethod
    def _file(cls, value: Any, info: ValidationInfo) -> Path | None:
        if value is not None and not isinstance(value, (str, Path)):
            raise ValueError(f"expected a file path string, found {type(value).__name__} {value!r}")
        cls._check_presence("file", value, info)
        if value is None:
            return None
        return _scene_file(value, info, "mesh file", read_mesh, "cannot read a triangle mesh from")

    @field_validator("scale", mode="plain")
    @classmethod
    def _scale(cls, value: Any) -> float | list[float]:
        return _positive_scale(value)

    @field_validator("material")
    @classmethod
    def _texture_needs_coordinates(cls, value: Any, info: ValidationInfo) -> Any:
        shape = info.data.get("shape")
        if getattr(value, "texture", None) is None or shape is None:
            return value
        if shape not in TEXTURED_SHAPES:
            raise ValueError(f"a texture needs a shape with texture coordinates ({', '.join(TEXTURED_SHAPES)}), "
                             f"found a {shape}")
        scale = np.broadcast_to(np.asarray(info.data.get("scale", 1.0), dtype=np.float64), (3,))
        if shape == "sphere" and np.ptp(scale) > 1e-12 * scale.max():
            raise ValueError(f"a texture needs a uniformly scaled sphere (an ellipsoid has no texture coordinates), "
                             f"found scale = {info.data.get('scale')}")
        return value

    @field_validator("keyframes")
    @classmethod
    def _keys_in_order(cls, value: list[Keyframe]) -> list[Keyframe]:
        times = [k.time_s for k in value]
        if any(b <= a for a, b in zip(times, times[1:])):
            raise ValueError(f"keyframe times must increase strictly, found {times}")
        return value

    # --- animation --------------------------------------------------------------------------------------------
    @property
    def moves(self) -> bool:
        """Whether the object has keyframes (it may still hold one pose)."""
        return bool(self.keyframes)

    def at(self, t: float) -> "ObjectConfig":
        """The object posed at time ``t`` (seconds), without keyframes; itself when it has none.

        Each of ``translate``, ``rotate_deg`` and ``scale`` is interpolated over the keys; a key that leaves a
        field out has the object's own value there.
        """
        if not self.keyframes:
            return self
        pose = {}
        times = np.array([k.time_s for k in self.keyframes])
        for name in ("translate", "rotate_deg", "scale"):
            if all(getattr(k, name) is None for k in self.keyframes):
                continue
            values = np.array([np.broadcast_to(np.asarray(getattr(self, name) if getattr(k, name) is None
                                                          else getattr(k, name), np.float64), (3,))
                               for k in self.keyframes])
            pose[name] = interpolate(times, values, float(t), self.interpolation).tolist()
        return self.model_copy(update={**pose, "keyframes": []})

    # --- geometry ---------------------------------------------------------------------------------------------
    @property
    def scale3(self) -> np.ndarray:
        """Scale factors (3,) along the local axes."""
        return np.broadcast_to(np.asarray(self.scale, dtype=np.float64), (3,)).copy()

    def rotation(self) -> np.ndarray:
        """Rotation matrix (3, 3) of ``rotate_deg`` (x, then y, then z about the world axes)."""
        return _rotation(self.rotate_deg)

    def to_world(self) -> np.ndarray:
        """Object-to-world matrix: scale, then rotate about x, y, z, then translate.

        The primitive's own extent (``size``, ``radius``, ``height``) is not included: the local geometry is
        the actual-size object centred at the origin.

        Returns:
            (4, 4) float64 homogeneous matrix, metres.
        """
        m = np.eye(4)
        m[:3, :3] = self.rotation() @ np.diag(self.scale3)
        m[:3, 3] = self.translate
        return m

    def triangle_mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """Local-space triangles of a cylinder (capped, ``CYLINDER_SECTIONS`` facets) or a mesh object.

        Returns:
            vertices (N, 3) float64 in local coordinates (metres, before :meth:`to_world`), faces (F, 3) int64.

        Raises:
            ValueError: for the other shapes.
        """
        if self.shape == "cylinder":
            import trimesh

            tm = trimesh.creation.cylinder(radius=self.radius, height=self.height, sections=CYLINDER_SECTIONS)
            return np.asarray(tm.vertices, np.float64), np.asarray(tm.faces, np.int64)
        if self.shape == "mesh":
            return read_mesh(self.file)
        raise ValueError(f"{self.name}: a {self.shape} is not a triangle mesh")

    def bounds(self) -> np.ndarray:
        """World-space axis-aligned bounding box.

        Exact for boxes, rectangles, spheres (ellipsoids under non-uniform scale) and cylinders (the true
        cylinder, not its facets); the transformed vertices' extent for meshes.

        Returns:
            (2, 3) float64: [min corner, max corner], metres.
        """
        m = self.to_world()
        a, t = m[:3, :3], m[:3, 3]
        if self.shape in ("box", "rectangle"):
            half = np.zeros(3)
            half[: len(self.size)] = np.asarray(self.size) / 2
            ext = np.abs(a) @ half
        elif self.shape == "sphere":
            ext = self.radius * np.linalg.norm(a, axis=1)
        elif self.shape == "cylinder":
            ext = np.abs(a[:, 2]) * self.height / 2 + self.radius * np.hypot(a[:, 0], a[:, 1])
        else:
            v = self.triangle_mesh()[0] @ a.T + t
            return np.stack([v.min(0), v.max(0)])
        return np.stack([t - ext, t + ext])


def _in_half_space(side: str):
    def check(obj: ObjectConfig) -> ObjectConfig:
        if side == "real" and obj.material.type == "emitter":
            raise ValueError(f"{obj.name!r}: an emitter is a synthetic object; the real side's light is [light]")
        lo, hi = obj.bounds()
        if side == "real" and lo[2] <= 0:
            raise ValueError(f"a real object must lie in z > 0; {obj.name!r} spans z in [{lo[2]:.4g}, {hi[2]:.4g}] m")
        if side == "synthetic" and hi[2] >= 0:
            raise ValueError(f"a synthetic object must lie in z < 0; {obj.name!r} spans z in "
                             f"[{lo[2]:.4g}, {hi[2]:.4g}] m")
        return obj

    return AfterValidator(check)


RealObject = Annotated[ObjectConfig, _in_half_space("real")]
SyntheticObject = Annotated[ObjectConfig, _in_half_space("synthetic")]


class _SceneBase(_Model):
    """What every scene has: the rig file's nominal values, the view camera, the point light, the render
    settings and the time line; the subclasses add the objects.

    Attributes:
        rig: light field interface hardware (nominal values; defaults: the paper's rig).
        view: the view camera.
        lights: the real point lights (their positions as measured by hand): ``[light]`` (one) or
            ``[[light]]`` (several) in the file; empty: the scene is lit by its emitting synthetic objects alone
            (through the projector on the real side).
        render: render settings.
        animation: the time line of keyframed objects (``[animation]``), or None for a still scene.
        source: the TOML file it was loaded from, or None.
    """

    rig: RigConfig = Field(default_factory=RigConfig)
    view: ViewConfig = Field(default_factory=ViewConfig)
    lights: list[LightConfig] = Field(default_factory=list, validation_alias=AliasChoices("light", "lights"),
                                      max_length=MAX_LIGHTS)
    render: RenderConfig = Field(default_factory=RenderConfig)
    animation: AnimationConfig | None = None
    source: Path | None = None

    def _sides(self) -> dict[str, list[ObjectConfig]]:
        return {side: getattr(self, side) for side in ("real", "synthetic") if side in type(self).model_fields}

    @property
    def moving(self) -> bool:
        """Whether any object has keyframes."""
        return any(o.moves for objs in self._sides().values() for o in objs)

    def frame_times(self) -> np.ndarray:
        """(F,) float64 frame times of the ``[animation]``, seconds; ``[0.0]`` for a still scene."""
        return self.animation.frame_times() if self.animation is not None else np.zeros(1)

    def at(self, t: float):
        """The scene at time ``t`` (seconds): every keyframed object posed (:meth:`ObjectConfig.at`)."""
        if not self.moving:
            return self
        return self.model_copy(update={side: [o.at(t) for o in objs] for side, objs in self._sides().items()})

    @property
    def emitters(self) -> list[ObjectConfig]:
        """The synthetic objects that emit light."""
        return [o for o in self.synthetic if o.material.type == "emitter"]

    @field_validator("lights", mode="before")
    @classmethod
    def _one_or_several(cls, value):
        # ``[light]`` is one table, ``[[light]]`` a list of them; None (from older code) is no light
        return [] if value is None else [value] if isinstance(value, (dict, LightConfig)) else value

    @model_validator(mode="after")
    def _something_lights_it(self):
        if not self.lights and not self.emitters:
            raise ValueError("nothing lights the scene: give a [light] table (the real point light) or a synthetic "
                             "object with material type = 'emitter'")
        return self

    @model_validator(mode="after")
    def _animation_fits(self):
        sides = self._sides()
        keyed = [(side, i, o) for side, objs in sides.items() for i, o in enumerate(objs) if o.moves]
        if not keyed:
            return self
        if self.animation is None:
            side, i, o = keyed[0]
            raise ValueError(f"{side}[{i}] ({o.name!r}) has keyframes, but the scene has no [animation] table "
                             "(duration_s, fps)")
        for side, i, o in keyed:
            late = [k.time_s for k in o.keyframes if k.time_s > self.animation.duration_s]
            if late:
                raise ValueError(f"{side}[{i}] ({o.name!r}).keyframes: time_s {late[0]} is after the end of the "
                                 f"animation (duration_s = {self.animation.duration_s})")
            times = np.union1d(self.animation.frame_times(), [k.time_s for k in o.keyframes])
            for t in times:
                posed = o.at(float(t))
                if np.min(posed.scale3) <= 0:
                    raise ValueError(f"{side}[{i}] ({o.name!r}): its interpolated scale is not positive at "
                                     f"t = {t:.4g} s ({posed.scale3.tolist()})")
                lo, hi = posed.bounds()
                if (side == "real" and lo[2] <= 0) or (side == "synthetic" and hi[2] >= 0):
                    half = "z > 0" if side == "real" else "z < 0"
                    raise ValueError(f"{side}[{i}] ({o.name!r}) leaves its half-space ({half}) at t = {t:.4g} s: "
                                     f"it spans z in [{lo[2]:.4g}, {hi[2]:.4g}] m")
        return self


class SyntheticScene(_SceneBase):
    """What the pipeline may know of a scene: the rig file's nominal values, the view camera, the point light as
    measured by hand, the render settings, the time line and the synthetic objects; never the real objects.

    Attributes:
        synthetic: objects of the synthetic half-space (bounding boxes in z < 0).
    """

    synthetic: list[SyntheticObject] = Field(default_factory=list)


class SceneConfig(_SceneBase):
    """A whole scene file, real objects included (for the simulated rig and its ground truth).

    Attributes:
        real: objects of the real half-space (bounding boxes in z > 0).
        synthetic: objects of the synthetic half-space (bounding boxes in z < 0).
        effect: the effect measured per verified frame (``[effect]``), or None; verification data, like the
            real objects, so the pipeline's part of the scene does not hold it.
    """

    real: list[RealObject] = Field(default_factory=list)
    synthetic: list[SyntheticObject] = Field(default_factory=list, validate_default=True)
    effect: EffectConfig | None = None

    @field_validator("synthetic")
    @classmethod
    def _some_object(cls, value: list[ObjectConfig], info: ValidationInfo) -> list[ObjectConfig]:
        real = info.data.get("real")
        if real is not None and not real and not value:
            raise ValueError("a scene needs at least one [[real]] or [[synthetic]] object, found none")
        return value

    @model_validator(mode="after")
    def _effect_names_objects(self):
        e = self.effect
        if e is None:
            return self
        real, synthetic = [o.name for o in self.real], [o.name for o in self.synthetic]
        if real.count(e.on) != 1:
            raise ValueError(f"effect.on: expected the name of one [[real]] object ({', '.join(map(repr, real))}), "
                             f"found {e.on!r}" + (" (more than one object has it)" if e.on in real else ""))
        if synthetic.count(e.by) != 1:
            raise ValueError(f"effect.by: expected the name of one [[synthetic]] object "
                             f"({', '.join(map(repr, synthetic))}), found {e.by!r}"
                             + (" (more than one object has it)" if e.by in synthetic else ""))
        if e.kind == "shadow" and not self.lights and len(self.emitters) == 1 and self.emitters[0].name == e.by:
            raise ValueError(f"effect.by: {e.by!r} is the only light of the scene: it cannot shadow anything")
        return self

    def synthetic_part(self) -> SyntheticScene:
        """The part of the scene the pipeline is given (everything but the real objects)."""
        return SyntheticScene.model_construct(**{k: getattr(self, k) for k in SyntheticScene.model_fields})


def check_synthetic(scene) -> SyntheticScene:
    """``scene`` if it is the synthetic part of a scene, else a TypeError: the pipeline never gets real objects."""
    if not isinstance(scene, SyntheticScene):
        raise TypeError(f"the pipeline takes the synthetic part of a scene (SceneConfig.synthetic_part()), "
                        f"never the real objects; got {type(scene).__name__}")
    return scene


# --------------------------------------------------------------------------------------------------------------
# Loading

def _material_tag(loc: tuple, i: int) -> bool:
    """``loc[i]`` is the material union's tag (``material.diffuse.albedo``), not a field."""
    return loc[i] in _MATERIAL_TAGS and i > 0 and loc[i - 1] == "material"


def _unknown_material(err: dict) -> str:
    if err.get("type") == "material_type" and isinstance(err.get("input"), dict):
        return f", found type = {err['input'].get('type')!r}"
    return ""


def _scene_error(name: str, exc: ValidationError) -> SceneError:
    return SceneError(validation_message(name, exc, root="<scene>", is_tag=_material_tag, extra=_unknown_material))


def load_scene(path: str | Path) -> SceneConfig:
    """Read and validate a scene TOML file.

    Args:
        path: the file; mesh paths inside it are relative to its folder.

    Returns:
        The validated scene, with ``source`` set to the file's absolute path.

    Raises:
        SceneError: unreadable file, not UTF-8 (a leading byte order mark is fine), malformed TOML or an
            invalid field; one message naming the file and the field path (e.g. ``real[0].material.roughness``).
    """
    path = Path(path)
    data = read_toml(path, "scene file", SceneError)
    if "source" in data:
        raise SceneError(f"{path}: source: not a scene field (it is set by the loader), found {data['source']!r}")
    data["source"] = path.resolve()
    try:
        return SceneConfig.model_validate(data, context={"base_dir": path.resolve().parent})
    except ValidationError as exc:
        raise _scene_error(str(path), exc) from None


def with_overrides(scene: SceneConfig | SyntheticScene, **changes: Any) -> SceneConfig | SyntheticScene:
    """A copy of a scene with some fields changed, validated again.

    Table-valued fields (``rig``, ``view``, ``light``, ``render``) given as dicts are merged into the current
    table; other values (including whole config objects and the object lists) replace it.

    Args:
        scene: the scene.
        **changes: e.g. ``view={"resolution": [256, 192]}``, ``render={"gt_spp": 16}``,
            ``rig=scene.rig.model_copy(update=...)``, ``synthetic=[]``.

    Returns:
        A new validated scene of the same type.

    Raises:
        SceneError: unknown field or invalid value (message names the scene's file, or ``<scene>``).
    """
    data = scene.model_dump()
    for key, value in changes.items():
        if isinstance(value, BaseModel):
            value = value.model_dump()
        elif isinstance(value, (list, tuple)):
            value = [v.model_dump() if isinstance(v, BaseModel) else v for v in value]
        if isinstance(value, dict) and isinstance(data.get(key), dict):
            data[key] = {**data[key], **value}
        else:
            data[key] = value
    base = scene.source.parent if scene.source else None
    try:
        return type(scene).model_validate(data, context={"base_dir": base})
    except ValidationError as exc:
        raise _scene_error(str(scene.source) if scene.source else "<scene>", exc) from None


_BUILTIN_PACKAGE = "lftransfer.scenes"


def builtin_scenes() -> list[str]:
    """Names of the scene files shipped with the package (``fig4``, ...), sorted."""
    root = resources.files(_BUILTIN_PACKAGE)
    return sorted(p.name[: -len(".toml")] for p in root.iterdir() if p.name.endswith(".toml"))


def builtin_scene(name: str = "fig4") -> Path:
    """Path of a scene TOML shipped with the package.

    Args:
        name: scene name without ``.toml`` (``"fig4"`` is the paper's Fig. 4 scene).

    Returns:
        The file's path (pass it to :func:`load_scene`).

    Raises:
        SceneError: unknown name; the message lists the available scenes.
    """
    available = builtin_scenes()
    if not re.fullmatch(r"[A-Za-z0-9_\-]+", name or "") or name not in available:
        raise SceneError(f"{name}: no built-in scene of that name; available: {', '.join(available)}")
    return Path(str(resources.files(_BUILTIN_PACKAGE) / f"{name}.toml"))
