"""Scene files: the TOML format, its validated models and the built-in scenes (``fig4``).

Example:
    >>> from lftransfer.scenes import builtin_scene, load_scene
    >>> scene = load_scene(builtin_scene("fig4"))
    >>> scene.real[0].name
    'red block'
"""

from lftransfer.scenes.assets import read_mesh
from lftransfer.scenes.builtins import builtin_scene, builtin_scenes
from lftransfer.scenes.loader import SceneError, load_scene, with_overrides
from lftransfer.scenes.resolution import QUICK_FACTOR, check_resolution, quick_scene
from lftransfer.scenes.models import (
    DiffuseMaterial,
    EffectConfig,
    EmitterMaterial,
    GlossyMaterial,
    LightConfig,
    Material,
    MetalMaterial,
    RenderConfig,
    RigConfig,
    ViewConfig,
)
from lftransfer.scenes.objects import ObjectConfig
from lftransfer.scenes.scene import SceneConfig, SyntheticScene, check_synthetic

__all__ = [
    "QUICK_FACTOR",
    "DiffuseMaterial",
    "EffectConfig",
    "EmitterMaterial",
    "GlossyMaterial",
    "LightConfig",
    "Material",
    "MetalMaterial",
    "ObjectConfig",
    "RenderConfig",
    "RigConfig",
    "SceneConfig",
    "SceneError",
    "SyntheticScene",
    "ViewConfig",
    "builtin_scene",
    "builtin_scenes",
    "check_resolution",
    "check_synthetic",
    "load_scene",
    "quick_scene",
    "read_mesh",
    "with_overrides",
]
