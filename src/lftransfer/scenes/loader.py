"""Loading scene files: :func:`load_scene` and :func:`with_overrides`, whose errors name the file and the field
(:class:`SceneError`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError

from lftransfer.scenes.models import _MATERIAL_TAGS
from lftransfer.scenes.scene import SceneConfig, SyntheticScene
from lftransfer.validation import read_toml, validation_message

__all__ = ["SceneError", "load_scene", "with_overrides"]


class SceneError(ValueError):
    """An invalid scene file.

    The message reads ``"<file>: <field path>: <what was expected, what was found>"``, e.g.
    ``"fig4.toml: real[0].material.roughness: Input should be less than or equal to 1, found 1.5"``.
    """


def _material_tag(loc: tuple, i: int) -> bool:
    """``loc[i]`` is the material union's tag (``material.diffuse.albedo``), not a field."""
    return loc[i] in _MATERIAL_TAGS and i > 0 and loc[i - 1] == "material"


def _unknown_material(err: dict) -> str:
    if err.get("type") == "material_type" and isinstance(err.get("input"), dict):
        return f", found type = {err['input'].get('type')!r}"
    return ""


def _scene_error(name: str, exc: ValidationError, model: type[BaseModel], data: dict) -> SceneError:
    return SceneError(validation_message(name, exc, root="<scene>", is_tag=_material_tag, extra=_unknown_material,
                                         model=model, data=data))


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
    if "lights" in data:          # the model's own name for its lights; the file's table is [light] or [[light]]
        raise SceneError(f"{path}: lights: unknown key (not a field of this table; did you mean 'light'? one "
                         f"[light] table, or a [[light]] table per light)")
    data["source"] = path.resolve()
    try:
        return SceneConfig.model_validate(data, context={"base_dir": path.resolve().parent})
    except ValidationError as exc:
        raise _scene_error(str(path), exc, SceneConfig, data) from None


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
        raise _scene_error(str(scene.source) if scene.source else "<scene>", exc, type(scene), data) from None
