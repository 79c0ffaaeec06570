"""The scene files shipped with the package (``fig4``, ...): their names and paths."""

from __future__ import annotations

import re
from importlib import resources
from pathlib import Path

from lftransfer.scenes.loader import SceneError

__all__ = ["builtin_scene", "builtin_scenes"]


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
