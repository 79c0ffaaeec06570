"""Scene objects (``lftransfer.scenes.ObjectConfig``) as Mitsuba scene dicts.

Every object becomes one Mitsuba shape whose dict key, and therefore shape id (``shape.id()``), is derived from
the object's name by :func:`object_keys`: lower case, each run of characters other than ``a-z0-9`` replaced by
``_`` (``"red block"`` -> ``"red_block"``); a name that repeats an earlier key, or is ``type``, gets a suffix
``_2``, ``_3``, ... in list order. Shapes of a loaded scene can then be found again with
``{s.id(): s for s in scene.shapes()}`` or by comparing ``si.shape`` with ``mi.ShapePtr(shape)``.

Primitives map to Mitsuba's own shapes (``sphere``, ``cube``, ``rectangle``); cylinders, meshes and spheres with a
non-uniform scale become triangle meshes. Triangle meshes are written once as binary PLY files into a cache
folder (``$LFT_CACHE_DIR/meshes`` or ``~/.cache/lftransfer/meshes``), named by a hash of their content, and
referenced by a ``ply`` shape dict, so that every result of this module is a plain dict that callers may copy or
extend. The PLY holds the object's local geometry; the object's transform is the shape's ``to_world``.
"""

from __future__ import annotations

import hashlib
import os
import re
import tempfile
from pathlib import Path
from typing import Sequence

import numpy as np

from lftransfer.backend import mitsuba

__all__ = ["albedo_dict", "board_shapes", "bsdf_dict", "emitter_dict", "lens_array_absorber", "shape_dict", "scene_dict", "object_keys",
           "mesh_cache_dir", "write_ply",
           "SPHERE_SUBDIVISIONS"]

SPHERE_SUBDIVISIONS = 4        # icosphere subdivisions of a non-uniformly scaled sphere (5120 triangles)
_RESERVED_KEYS = {"type"}


def _rgb(value) -> dict:
    return {"type": "rgb", "value": [float(x) for x in value]}


def bsdf_dict(material) -> dict:
    """Mitsuba BSDF dict of a material.

    - diffuse -> ``diffuse`` with ``reflectance`` = albedo (times the texture, :func:`albedo_dict`);
    - glossy -> ``roughplastic`` (GGX, ``alpha`` = roughness), or ``plastic`` when roughness is 0, with
      ``diffuse_reflectance`` = albedo (times the texture) and ``specular_reflectance`` = specular;
    - metal -> ``roughconductor`` (material ``none``, GGX, ``alpha`` = roughness), or ``conductor`` when
      roughness is 0, with ``specular_reflectance`` = specular;
    - emitter -> a black ``diffuse`` surface (its light is the shape's ``area`` emitter, :func:`emitter_dict`).

    Args:
        material: ``DiffuseMaterial``, ``GlossyMaterial`` or ``MetalMaterial``.

    Returns:
        A dict for ``mi.load_dict``.

    Raises:
        ValueError: unknown material type.
    """
    kind = material.type
    if kind == "diffuse":
        return {"type": "diffuse", "reflectance": albedo_dict(material)}
    if kind == "glossy":
        d = {"type": "plastic", "diffuse_reflectance": albedo_dict(material),
             "specular_reflectance": _rgb(material.specular)}
        if material.roughness > 0:
            d.update(type="roughplastic", distribution="ggx", alpha=float(material.roughness))
        return d
    if kind == "metal":
        d = {"type": "conductor", "material": "none", "specular_reflectance": _rgb(material.specular)}
        if material.roughness > 0:
            d.update(type="roughconductor", distribution="ggx", alpha=float(material.roughness))
        return d
    if kind == "emitter":
        return {"type": "diffuse", "reflectance": _rgb([0.0, 0.0, 0.0])}
    raise ValueError(f"unknown material type {kind!r}")


def albedo_dict(material) -> dict:
    """Mitsuba texture dict of a material's diffuse albedo: ``rgb``, or with a ``texture`` a ``bitmap`` of the
    image's linear colours times the albedo (``raw``: no further colour conversion; bilinear, repeating).

    The image is stored upside down, so that Mitsuba's v = 0 (its first row) is the image's bottom row: the image
    appears upright on a rectangle seen from its front (normal) side with its local +y axis up, u along local x
    and v along local y.

    Args:
        material: ``DiffuseMaterial`` or ``GlossyMaterial``.

    Returns:
        A dict for ``mi.load_dict`` (inside a BSDF dict).
    """
    texture = getattr(material, "texture", None)
    if texture is None:
        return _rgb(material.albedo)
    from lftransfer.scenes.format import read_texture

    mi = mitsuba()
    data = read_texture(texture)[::-1] * np.asarray(material.albedo, np.float32)
    return {"type": "bitmap", "data": mi.TensorXf(np.ascontiguousarray(data, dtype=np.float32)), "raw": True}


def emitter_dict(material) -> dict | None:
    """Mitsuba ``area`` emitter dict of an emitter material (``radiance`` per RGB channel), or None for a material
    that does not emit."""
    if material.type != "emitter":
        return None
    return {"type": "area", "radiance": _rgb(material.radiance)}


def mesh_cache_dir() -> Path:
    """Folder of cached PLY meshes: ``$LFT_CACHE_DIR/meshes`` or ``~/.cache/lftransfer/meshes`` (created)."""
    root = Path(os.environ.get("LFT_CACHE_DIR", Path.home() / ".cache" / "lftransfer"))
    path = root / "meshes"
    path.mkdir(parents=True, exist_ok=True)
    return path


def write_ply(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray | None = None) -> Path:
    """Write a triangle mesh as a binary little-endian PLY into :func:`mesh_cache_dir`, once per content.

    The file is named by the SHA-256 of its bytes and written atomically (temporary file, then rename), so
    concurrent writers and readers never see a partial file.

    Args:
        vertices: (N, 3) positions, metres (stored as float32).
        faces: (F, 3) vertex indices.
        normals: optional (N, 3) vertex normals (stored as float32); without them Mitsuba shades with
            face normals only if the shape dict asks for it (see :func:`shape_dict`).

    Returns:
        Path of the PLY file.
    """
    v = np.ascontiguousarray(vertices, dtype="<f4").reshape(-1, 3)
    f = np.ascontiguousarray(faces, dtype="<i4").reshape(-1, 3)
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError(f"face indices outside [0, {len(v)})")
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    vrec = np.empty(len(v), dtype=fields)
    vrec["x"], vrec["y"], vrec["z"] = v.T
    if normals is not None:
        n = np.ascontiguousarray(normals, dtype="<f4").reshape(-1, 3)
        vrec["nx"], vrec["ny"], vrec["nz"] = n.T
    frec = np.empty(len(f), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    frec["n"] = 3
    frec["i"] = f
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(v)}"]
    header += [f"property float {name}" for name, _ in fields]
    header += [f"element face {len(f)}", "property list uchar int vertex_indices", "end_header", ""]
    data = "\n".join(header).encode("ascii") + vrec.tobytes() + frec.tobytes()
    folder = mesh_cache_dir()
    path = folder / f"{hashlib.sha256(data).hexdigest()[:32]}.ply"
    if path.is_file() and path.stat().st_size == len(data):
        return path
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tmp-", suffix=".ply")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _cylinder(obj) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Capped cylinder with per-corner normals: smooth (radial) on the side, flat on the caps."""
    v, f = obj.triangle_mesh()
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    fn /= np.linalg.norm(fn, axis=1, keepdims=True)
    corners = v[f].reshape(-1, 3)                                   # unmerged: 3 vertices per face
    normals = np.repeat(fn, 3, axis=0)
    side = np.repeat(np.abs(fn[:, 2]) < 0.5, 3)
    radial = corners[side].copy()
    radial[:, 2] = 0.0
    normals[side] = radial / np.linalg.norm(radial, axis=1, keepdims=True)
    return corners, np.arange(len(corners)).reshape(-1, 3), normals


def _ellipsoid(obj) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    import trimesh

    tm = trimesh.creation.icosphere(subdivisions=SPHERE_SUBDIVISIONS, radius=1.0)
    unit = np.asarray(tm.vertices, np.float64)
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    return unit * obj.radius, np.asarray(tm.faces, np.int64), unit


def shape_dict(obj) -> dict:
    """Mitsuba shape dict of one object, with its BSDF.

    - sphere -> ``sphere`` with ``to_world`` = the object's transform times its radius (an icosphere mesh
      when the scale is not uniform: Mitsuba's sphere takes no non-uniform scale);
    - box -> ``cube`` (the [-1, 1]^3 cube) with ``to_world`` including the size / 2 scale;
    - rectangle -> ``rectangle`` ([-1, 1]^2 in the local xy plane, normal +z), size / 2 scale included;
    - cylinder -> capped triangle mesh (``ObjectConfig.triangle_mesh``), radial normals on the side;
    - mesh -> the file's triangles (trimesh, ``force="mesh"``), shaded with face normals.

    Triangle meshes are ``ply`` dicts of a cached file (see the module docs).

    Args:
        obj: ``lftransfer.scenes.ObjectConfig``.

    Returns:
        A dict for ``mi.load_dict`` (inside a scene dict).
    """
    d = _geometry_dict(obj)
    emitter = emitter_dict(obj.material)
    if emitter is not None:
        d["emitter"] = emitter
    return d


def _geometry_dict(obj) -> dict:
    mi = mitsuba()
    m = obj.to_world()
    bsdf = bsdf_dict(obj.material)

    def transform(matrix: np.ndarray):
        return mi.ScalarTransform4f(np.asarray(matrix, dtype=np.float64).tolist())

    if obj.shape == "box":
        return {"type": "cube", "to_world": transform(m @ np.diag([*(np.asarray(obj.size) / 2), 1.0])),
                "bsdf": bsdf}
    if obj.shape == "rectangle":
        sx, sy = np.asarray(obj.size) / 2
        return {"type": "rectangle", "to_world": transform(m @ np.diag([sx, sy, 1.0, 1.0])), "bsdf": bsdf}
    if obj.shape == "sphere" and np.ptp(obj.scale3) <= 1e-12 * obj.scale3.max():
        return {"type": "sphere", "to_world": transform(m @ np.diag([obj.radius] * 3 + [1.0])), "bsdf": bsdf}
    if obj.shape == "sphere":
        v, f, n = _ellipsoid(obj)
        return {"type": "ply", "filename": str(write_ply(v, f, n)), "to_world": transform(m), "bsdf": bsdf}
    if obj.shape == "cylinder":
        v, f, n = _cylinder(obj)
        return {"type": "ply", "filename": str(write_ply(v, f, n)), "to_world": transform(m), "bsdf": bsdf}
    if obj.shape == "mesh":
        v, f = obj.triangle_mesh()
        return {"type": "ply", "filename": str(write_ply(v, f)), "face_normals": True, "to_world": transform(m),
                "bsdf": bsdf}
    raise ValueError(f"{obj.name}: unknown shape {obj.shape!r}")


def object_keys(objects: Sequence) -> list[str]:
    """Scene-dict keys (= Mitsuba shape ids) of objects, in order (rule in the module docs).

    Args:
        objects: ``ObjectConfig`` list (only ``name`` is read).

    Returns:
        One unique key per object, e.g. ``["red_block", "green_cube", "red_block_2"]``.
    """
    used = set(_RESERVED_KEYS)
    keys = []
    for obj in objects:
        base = re.sub(r"[^a-z0-9]+", "_", str(obj.name).lower()).strip("_") or "object"
        key, n = base, 1
        while key in used:
            n += 1
            key = f"{base}_{n}"
        used.add(key)
        keys.append(key)
    return keys


def scene_dict(objects: Sequence, *, extra: dict | None = None) -> dict:
    """Mitsuba scene dict of objects, plus extra entries.

    Args:
        objects: ``ObjectConfig`` list; each becomes ``key: shape_dict(obj)`` with ``key`` from
            :func:`object_keys`.
        extra: more entries (sensors, emitters, integrators, shapes), added as they are.

    Returns:
        ``{"type": "scene", ...}``; loads with ``mi.load_dict(d, optimize=False)``.

    Raises:
        ValueError: an extra key equals ``type`` or an object's key.
    """
    d: dict = {"type": "scene"}
    for key, obj in zip(object_keys(objects), objects):
        d[key] = shape_dict(obj)
    for key, value in (extra or {}).items():
        if key in d:
            raise ValueError(f"scene_dict: extra entry {key!r} clashes with an object's key or 'type'")
        d[key] = value
    return d


def lens_array_absorber(array, to_world: np.ndarray | None = None) -> dict:
    """Mitsuba shape dict of the lens array seen from the real side: a black rectangle just behind z = 0.

    Args:
        array: ``LensArray`` (its extent, in the array's own frame).
        to_world: (4, 4) the array's frame -> the scene's (another interface's array); None: the same frame.
    """
    mi = mitsuba()
    xmin, xmax, ymin, ymax = array.extent()
    place = mi.ScalarTransform4f() if to_world is None else mi.ScalarTransform4f(np.asarray(to_world).tolist())
    return {"type": "rectangle",
            "to_world": place.translate([(xmin + xmax) / 2, (ymin + ymax) / 2, -5e-4])
            .scale([(xmax - xmin) / 2, (ymax - ymin) / 2, 1.0]),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}}


SCREEN_TEXELS = 16          # texels per chessboard square of a translucent board's printed chart


def board_shapes(to_world: np.ndarray, albedo: float, chart: tuple[int, int, float] | None = None,
                 transmission: float = 0.0) -> dict:
    """Mitsuba shape dicts of a flat diffuse calibration board, with an optional printed chessboard.

    Args:
        to_world: (4, 4) the board rectangle's ``to_world`` (:func:`lftransfer.optics.geometry.rectangle_to_world`).
        albedo: the board's diffuse reflectance.
        chart: (columns, rows, square metres) of a chessboard printed at its true size on the board's centre
            (dark squares of reflectance ``albedo / 4``), or None.
        transmission: 0 for an opaque board; else a rear-projection screen that passes this share of the light it
            scatters to its other side and reflects the rest, both diffusely, so that a camera behind it sees what is
            drawn on its front; the chart is then printed into the screen (one rectangle, a texture).

    Returns:
        ``{"board": ..., "chart": ...}`` shape dicts (``{"board": ...}`` only for a translucent board).
    """
    mi = mitsuba()
    to_world = np.asarray(to_world, np.float64)
    if transmission > 0:
        tex = {"type": "rgb", "value": [albedo] * 3}
        if chart is not None:
            tex = {"type": "bitmap", "bitmap": mi.Bitmap(_screen_texture(to_world, albedo, chart)),
                   "filter_type": "nearest", "wrap_mode": "clamp", "raw": True}
        # Mitsuba 3.9 has no plain diffuse transmitter; its thin principled BSDF with no specular lobe (eta 1) and
        # full roughness is one: diffuse reflection and transmission, diff_trans / 2 of the light passing through
        bsdf = {"type": "principledthin", "base_color": tex, "diff_trans": 2.0 * float(transmission),
                "spec_trans": 0.0, "eta": 1.0001, "roughness": 1.0}
        return {"board": {"type": "rectangle", "to_world": mi.ScalarTransform4f(to_world.tolist()), "bsdf": bsdf}}
    shapes = {"board": {"type": "rectangle", "to_world": mi.ScalarTransform4f(to_world.tolist()),
                        "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [albedo] * 3}}}}
    if chart is not None:
        cols, rows, square = chart
        ex, ey, n = (to_world[:3, i] / np.linalg.norm(to_world[:3, i]) for i in range(3))
        m = to_world.copy()
        m[:3, 0] = ex * cols * square / 2
        m[:3, 1] = ey * rows * square / 2
        m[:3, 3] = to_world[:3, 3] + 1e-4 * n
        texture = {"type": "checkerboard", "color0": {"type": "rgb", "value": [albedo / 4] * 3},
                   "color1": {"type": "rgb", "value": [albedo] * 3},
                   "to_uv": mi.ScalarTransform4f().scale([cols / 2, rows / 2, 1.0])}
        shapes["chart"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f(m.tolist()),
                           "bsdf": {"type": "diffuse", "reflectance": texture}}
    return shapes


def _screen_texture(to_world: np.ndarray, albedo: float, chart: tuple[int, int, float]) -> np.ndarray:
    """(H, W, 3) float32 texture of a board of ``to_world``'s size with the chessboard ``chart`` printed on its
    centre, as :func:`board_shapes` prints it on an opaque board (the dark squares at ``albedo / 4``, the top-left
    square dark); :data:`SCREEN_TEXELS` texels per square."""
    cols, rows, square = chart
    width, height = (2 * np.linalg.norm(to_world[:3, i]) for i in range(2))
    texel = square / SCREEN_TEXELS
    w, h = max(1, int(round(width / texel))), max(1, int(round(height / texel)))
    u = (np.arange(w) + 0.5) * texel - width / 2                # metres from the centre, along the board's x
    v = (np.arange(h) + 0.5) * texel - height / 2
    i = np.floor(u / square + cols / 2)
    j = np.floor(v / square + rows / 2)
    inside = ((i >= 0) & (i < cols))[None, :] & ((j >= 0) & (j < rows))[:, None]
    dark = ((i[None, :] + j[:, None]) % 2 == 0) & inside
    img = np.where(dark, albedo / 4, albedo).astype(np.float32)
    return np.repeat(img[::-1, :, None], 3, axis=2)            # row 0 of a bitmap is the top (v = 1)
