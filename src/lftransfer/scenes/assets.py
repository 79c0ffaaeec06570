"""Files a scene names: triangle meshes and textures, read and cached, and the check that a scene's file path
exists and can be read (relative to the scene file's folder).

Readers are cached by path, size and modification time, so an edited file is read again.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationInfo

__all__ = ["read_mesh", "read_texture"]


# --------------------------------------------------------------------------------------------------------------
# Textures

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


# --------------------------------------------------------------------------------------------------------------
# Meshes

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
