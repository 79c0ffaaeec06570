"""Scene files: the TOML format, its validated models and the built-in scenes (``fig4``).

Example:
    >>> from lftransfer.scenes import builtin_scene, load_scene
    >>> scene = load_scene(builtin_scene("fig4"))
    >>> scene.real[0].name
    'red block'
"""

from lftransfer.scenes.format import (
    DiffuseMaterial,
    EffectConfig,
    EmitterMaterial,
    GlossyMaterial,
    LightConfig,
    Material,
    MetalMaterial,
    ObjectConfig,
    RenderConfig,
    RigConfig,
    SceneConfig,
    SceneError,
    SyntheticScene,
    ViewConfig,
    builtin_scene,
    builtin_scenes,
    check_synthetic,
    load_scene,
    read_mesh,
    with_overrides,
)

__all__ = [
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
    "check_synthetic",
    "load_scene",
    "read_mesh",
    "with_overrides",
]
