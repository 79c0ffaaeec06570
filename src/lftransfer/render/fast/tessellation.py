"""Tessellation of the synthetic shapes into the cache's fine triangle soup: each object's local mesh refined until
its edges are at most ``max_edge`` long in the world (once per geometry), posed, with the corners its triangles share
(:class:`Tessellation`), and Mitsuba's texture coordinates at its vertices (:func:`texcoords`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.render.lights import jit_rays
from lftransfer.render.shapes import shape_dict

DEFAULT_MAX_EDGE = 0.006  # m


def texcoords(obj, vertices: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Mitsuba's texture coordinates of an object's exact shape at its cache vertices.

    Each vertex is read a hair inside its own triangle (so that a box's vertex takes its own face's
    coordinates), by a ray along -normal onto the exact shape; on a sphere, a triangle across the seam u = 0 / 1
    gets u + 1 on its small side (the texture repeats).

    Args:
        obj: ``ObjectConfig``.
        vertices: (3F, 3) cache vertices of the object (:func:`tessellate`), metres.
        normals: (3F, 3) their unit normals.

    Returns:
        (3F, 2) float32 (u, v).
    """
    mi = mitsuba()

    scene = mi.load_dict({"type": "scene", "shape": shape_dict(obj)}, parallel=False, optimize=False)
    tri = np.asarray(vertices, np.float64).reshape(-1, 3, 3)
    inner = (tri + 1e-3 * (tri.mean(axis=1, keepdims=True) - tri)).reshape(-1, 3)
    normals = np.asarray(normals, np.float64)
    o = inner + 1e-4 * normals
    d = -normals
    si = scene.ray_intersect(jit_rays(o, d))
    uv = np.array(si.uv, np.float64).T.reshape(-1, 3, 2)
    if obj.shape == "sphere":
        u = uv[..., 0]
        seam = (u.max(axis=1) - u.min(axis=1)) > 0.5
        u[seam] = np.where(u[seam] < 0.5, u[seam] + 1.0, u[seam])
    return uv.reshape(-1, 2).astype(np.float32)


@dataclass(frozen=True)
class Tessellation:
    """A scene object as the cache's triangle soup.

    Attributes:
        vertices: (3F, 3) float32 world positions, metres (triangle f owns vertices 3f, 3f+1, 3f+2).
        normals: (3F, 3) float32 unit normals (smooth on spheres, flat elsewhere).
        shared: (3F,) int64 index of each soup vertex among the object's distinct (position, normal) pairs
            (neighbouring triangles of one face share their corners): a quantity of the position and normal
            alone, such as irradiance, is computed once per distinct pair and read back as ``values[shared]``.
        distinct: number of distinct pairs (``shared.max() + 1``).
    """

    vertices: np.ndarray
    normals: np.ndarray
    shared: np.ndarray
    distinct: int


@dataclass(frozen=True)
class _LocalMesh:
    """An object's refined mesh in its local frame (before ``to_world``): what moving it does not change."""

    points: np.ndarray      # (P, 3) float64 local vertex positions
    faces: np.ndarray       # (F, 3) int64
    smooth: bool            # normals from the surface (sphere) rather than per face
    shared: np.ndarray      # (3F,) int64
    distinct: int


def _geometry_key(obj, max_edge: float) -> tuple:
    """What the local refined mesh depends on: the shape, its extent, the scale, the edge bound (not the pose)."""
    file = getattr(obj, "file", None)
    stamp = None
    if file is not None:       # a mesh file edited in place is read again
        st = Path(file).stat()
        stamp = (str(Path(file).resolve()), st.st_mtime_ns, st.st_size)
    return (obj.shape, tuple(np.atleast_1d(getattr(obj, "size", None) or ()).tolist()),
            getattr(obj, "radius", None), getattr(obj, "height", None), stamp, tuple(obj.scale3.tolist()),
            float(max_edge))


_LOCAL_MESHES: dict[tuple, _LocalMesh] = {}


def _local_mesh(obj, max_edge: float) -> _LocalMesh:
    """The object's local mesh refined until every edge is at most ``max_edge`` long in the world (memoised per
    geometry: an animation frame moves the object and re-uses it)."""
    import trimesh

    key = _geometry_key(obj, max_edge)
    if key in _LOCAL_MESHES:
        return _LOCAL_MESHES[key]
    smooth = obj.shape == "sphere"
    if obj.shape == "box":
        mesh = trimesh.creation.box(extents=obj.size)
    elif obj.shape == "rectangle":
        sx, sy = obj.size
        mesh = trimesh.Trimesh(vertices=[[-sx / 2, -sy / 2, 0], [sx / 2, -sy / 2, 0], [sx / 2, sy / 2, 0],
                                         [-sx / 2, sy / 2, 0]], faces=[[0, 1, 2], [0, 2, 3]], process=False)
    elif obj.shape == "sphere":
        mesh = trimesh.creation.icosphere(subdivisions=1, radius=obj.radius)
    else:   # cylinder, mesh
        v, f = obj.triangle_mesh()
        mesh = trimesh.Trimesh(vertices=v, faces=f, process=False)
    stretch = float(np.max(obj.scale3))           # local lengths grow at most this much in the world
    if smooth:   # curved: the facets are the geometry too, keep them within 0.1 % of the radius (edge <= r / 10)
        max_edge = min(max_edge, 0.1 * obj.radius * float(np.min(obj.scale3)))
    while mesh.edges_unique_length.max() * stretch > max_edge:
        mesh = mesh.subdivide()
        if smooth:   # keep subdivided vertices on the sphere
            mesh.vertices = mesh.vertices * (obj.radius / np.linalg.norm(mesh.vertices, axis=1, keepdims=True))
    faces = np.asarray(mesh.faces, np.int64)
    corner = faces.reshape(-1)
    if smooth:
        key_rows = corner[:, None]
    else:   # a corner is shared by the triangles of one face, not across an edge between faces
        normal_id = np.unique(np.round(np.asarray(mesh.face_normals), 4), axis=0, return_inverse=True)[1]
        key_rows = np.stack([corner, np.repeat(normal_id.reshape(-1), 3)], axis=1)
    _, shared = np.unique(key_rows, axis=0, return_inverse=True)
    shared = shared.reshape(-1).astype(np.int64)
    local = _LocalMesh(points=np.array(mesh.vertices, np.float64), faces=faces, smooth=smooth, shared=shared,
                       distinct=int(shared.max()) + 1 if len(shared) else 0)
    if len(_LOCAL_MESHES) >= 64:
        _LOCAL_MESHES.pop(next(iter(_LOCAL_MESHES)))
    _LOCAL_MESHES[key] = local
    return local


def tessellation(obj, max_edge: float = DEFAULT_MAX_EDGE) -> Tessellation:
    """World-space triangle soup of a scene object, refined to edges of at most ``max_edge``, with its shared
    corners (:class:`Tessellation`). The refinement is done once per geometry; a moved object is its local mesh
    transformed (normals by the inverse transpose: on a sphere the exact normals of the scaled surface).

    Args:
        obj: ``lftransfer.scenes.ObjectConfig``.
        max_edge: longest triangle edge, metres.

    Returns:
        :class:`Tessellation`.
    """
    local = _local_mesh(obj, max_edge)
    m = obj.to_world()
    linear, shift = m[:3, :3], m[:3, 3]
    normal_map = np.linalg.inv(linear).T
    points = local.points @ linear.T + shift
    vertices = points[local.faces.reshape(-1)]
    if local.smooth:
        normals = local.points[local.faces.reshape(-1)] @ normal_map.T       # radial in the local frame
    else:
        tri = local.points[local.faces]
        face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normals = np.repeat(face_n @ normal_map.T, 3, axis=0)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)   # degenerate faces: 0
    return Tessellation(vertices=vertices.astype(np.float32), normals=normals.astype(np.float32),
                        shared=local.shared, distinct=local.distinct)


def tessellate(obj, max_edge: float = DEFAULT_MAX_EDGE) -> tuple[np.ndarray, np.ndarray]:
    """World-space triangle soup of a scene object (:func:`tessellation` without the shared corners).

    Returns:
        vertices (3F, 3) float32 (triangle f owns vertices 3f, 3f+1, 3f+2), normals (3F, 3) float32 unit.
    """
    t = tessellation(obj, max_edge)
    return t.vertices, t.normals
