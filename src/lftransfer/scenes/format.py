"""The scene file format: pydantic models of a TOML scene and its loader (every name, re-exported).

A scene file describes the light field interface hardware (``[rig]``), the view camera (``[view]``), the real
point lights (``[light]``, or several ``[[light]]``), render settings (``[render]``) and the objects of the two
half-spaces (``[[real]]`` at z > 0, known only to the simulated rig; ``[[synthetic]]`` at z < 0, rendered). Units
are metres, degrees and linear RGB. ``docs/scene-format.md`` is the reference of every field.

The format lives in modules of one job each; this module keeps every name importable from here:

- :mod:`lftransfer.scenes.models`: field types and the tables (rig, view, light, render, materials, animation,
  effect).
- :mod:`lftransfer.scenes.objects`: the objects of the two half-spaces (shape, transform, keyframes, bounds).
- :mod:`lftransfer.scenes.scene`: whole scenes (:class:`SceneConfig`, :class:`SyntheticScene`).
- :mod:`lftransfer.scenes.assets`: mesh and texture files (:func:`read_mesh`, :func:`read_texture`).
- :mod:`lftransfer.scenes.loader`: :func:`load_scene`, :func:`with_overrides`, :class:`SceneError`.
- :mod:`lftransfer.scenes.builtins`: the scene files shipped with the package.

None of them imports Mitsuba: :mod:`lftransfer.render.shapes` turns the validated objects into Mitsuba scene
dicts.
"""

from __future__ import annotations

from lftransfer.scenes.assets import read_mesh, read_texture
from lftransfer.scenes.builtins import builtin_scene, builtin_scenes
from lftransfer.scenes.loader import SceneError, load_scene, with_overrides
from lftransfer.scenes.models import (
    MAX_LIGHTS,
    AnimationConfig,
    DiffuseMaterial,
    EffectConfig,
    EmitterMaterial,
    Float,
    GlossyMaterial,
    LightConfig,
    Material,
    MetalMaterial,
    NonNegFloat,
    NonNegVec3,
    PosFloat,
    PosInt,
    PosVec3,
    RenderConfig,
    RGBUnit,
    RigConfig,
    Size2,
    Unit,
    Vec3,
    ViewConfig,
)
from lftransfer.scenes.objects import (
    CYLINDER_SECTIONS,
    TEXTURED_SHAPES,
    Keyframe,
    ObjectConfig,
    RealObject,
    ShapeName,
    SyntheticObject,
)
from lftransfer.scenes.scene import SceneConfig, SyntheticScene, check_synthetic

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
    # also public here before the split
    "SyntheticScene",
    "check_synthetic",
    "CYLINDER_SECTIONS",
    "MAX_LIGHTS",
    "RealObject",
    "ShapeName",
    "SyntheticObject",
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
]
