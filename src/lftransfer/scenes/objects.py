"""The objects of a scene's two half-spaces (``[[real]]``, ``[[synthetic]]``): shape, transform, material and
keyframes, their world transform and bounds.

An object's local geometry is scaled, rotated about the world x, then y, then z axes
(:func:`lftransfer.optics.geometry.rotation_matrix`) and translated; metres and degrees.
"""

from __future__ import annotations

import math
import numbers
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import numpy as np
from pydantic import AfterValidator, Field, ValidationInfo, field_validator

from lftransfer.optics.geometry import rotation_matrix
from lftransfer.scenes.animation import Interpolation, interpolate
from lftransfer.scenes.assets import _scene_file, read_mesh
from lftransfer.scenes.interfaces import region_problem
from lftransfer.scenes.models import (
    DiffuseMaterial,
    Material,
    NonNegFloat,
    PosFloat,
    Vec3,
    _Model,
)

__all__ = [
    "ShapeName",
    "CYLINDER_SECTIONS",
    "TEXTURED_SHAPES",
    "Keyframe",
    "ObjectConfig",
    "RealObject",
    "SyntheticObject",
]

ShapeName = Literal["sphere", "box", "rectangle", "cylinder", "mesh"]
_SIZE_COMPONENTS = {"box": 3, "rectangle": 2}
_NEEDS = {"sphere": {"radius"}, "box": {"size"}, "rectangle": {"size"}, "cylinder": {"radius", "height"},
          "mesh": {"file"}}
CYLINDER_SECTIONS = 64          # facets around a cylinder's triangle mesh
TEXTURED_SHAPES = ("rectangle", "box", "sphere")   # shapes with texture coordinates (docs/scene-format.md)


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
        return rotation_matrix(self.rotate_deg)

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
    def check(obj: ObjectConfig, info: ValidationInfo) -> ObjectConfig:
        if side == "real" and obj.material.type == "emitter":
            raise ValueError(f"{obj.name!r}: an emitter is a synthetic object; the real side's light is [light]")
        # where it may stand depends on the scene's interfaces (validated before the objects)
        problem = region_problem(side, obj, (info.data or {}).get("interfaces") or [])
        if problem:
            raise ValueError(problem)
        return obj

    return AfterValidator(check)


RealObject = Annotated[ObjectConfig, _in_half_space("real")]
SyntheticObject = Annotated[ObjectConfig, _in_half_space("synthetic")]
