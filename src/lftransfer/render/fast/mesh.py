"""The cache's geometry: the synthetic objects as triangle soups loaded into one Mitsuba scene, with what a hit
needs to find its cache triangle and what its material does (:class:`CacheMesh`), moved in place when the objects
move."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.render.fast.materials import diffuse_lobe_table, is_glossy
from lftransfer.render.fast.tessellation import tessellation, texcoords
from lftransfer.render.lights import jit_array
from lftransfer.render.shapes import bsdf_dict, emitter_dict, object_keys, shape_dict


class CacheMesh:
    """The synthetic objects as the cache holds them: each reflecting object a triangle soup with edges of at most
    ``max_edge`` (:func:`~lftransfer.render.fast.tessellation.tessellation`) loaded as a Mitsuba mesh, each
    emitter its exact shape, all in one scene.

    Args:
        objects: scene objects (diffuse, glossy, metal or emitter).
        max_edge: longest triangle edge, metres.
        pinhole: (objects,) bool, the objects whose glossy lobes a view render reads from the cache points
            (:func:`lftransfer.render.fast.glossy.pinhole_objects`).

    Attributes:
        objects: the objects, posed.
        scene: the Mitsuba scene of the cache meshes and the emitters.
        vertices, normals: (M, 3) float32 cache points and their unit normals.
        rows: (M,) uint32 object index of each cache vertex.
        shared: (M,) int64 index of each cache vertex among the distinct (position, normal) pairs (irradiance and
            visibility are computed once per pair).
        one_of: (D,) int64 one cache vertex of each pair.
        pair: ``shared`` as mi.UInt32 (M,).
        tables: (objects, TABLE_NODES) float32 each object's :func:`diffuse_lobe_table`.
        reflects_diffuse: (objects,) bool, the objects with a diffuse lobe.
        glossy_objects: (objects,) bool, the glossy and metal objects.
        pinhole_objects: ``pinhole``.
        sids: (objects,) int64 registry id of each object's shape; scene_index: its index in ``scene.shapes()``.
        base: mi.UInt32 per registry id, the shape's first cache vertex.
        flags: mi.UInt32 per registry id, bit 0: cached, bit 1: glossy, bit 2: smooth, bit 3: a glossy lobe rough
            enough to be read from the cache points towards a pinhole.
        flags_size: length of ``base`` and ``flags``.
        keys: each object's shape key in the scene; bases: each object's first cache vertex.
    """

    def __init__(self, objects: Sequence, max_edge: float, pinhole: np.ndarray) -> None:
        mi = mitsuba()
        import drjit as dr

        self.objects = list(objects)
        self.max_edge = max_edge = float(max_edge)
        shapes, verts, norms, rows, tables, shared = {}, [], [], [], [], []
        base = distinct = 0
        bases = []
        info = []          # per object: (has cache vertices, glossy lobe, smooth lobe)
        for i, (key, obj) in enumerate(zip(object_keys(self.objects), self.objects)):
            tables.append(diffuse_lobe_table(obj.material))
            if emitter_dict(obj.material) is not None:
                # an emitter reflects nothing (no cache vertices) and keeps its exact shape, so that emitter
                # sampling draws directions over what it subtends (a sphere's cone), not over facets
                shapes[key] = shape_dict(obj)
                bases.append(base)
                info.append((False, False, False))
                continue
            cut = tessellation(obj, max_edge)
            v, n = cut.vertices, cut.normals
            textured = getattr(obj.material, "texture", None) is not None
            props = mi.Properties()
            props["bsdf"] = mi.load_dict(bsdf_dict(obj.material))
            mesh = mi.Mesh(key, len(v), len(v) // 3, props=props, has_vertex_normals=True,
                           has_vertex_texcoords=textured)
            params = mi.traverse(mesh)
            params["vertex_positions"] = mi.Float(v.ravel())
            params["vertex_normals"] = mi.Float(n.ravel())
            if textured:
                params["vertex_texcoords"] = mi.Float(texcoords(obj, v, n).ravel())
            params["faces"] = mi.UInt32(np.arange(len(v), dtype=np.uint32))
            params.update()
            shapes[key] = mesh
            verts.append(v)
            norms.append(n)
            rows.append(np.full(len(v), i, np.uint32))
            shared.append(cut.shared + distinct)
            distinct += cut.distinct
            bases.append(base)
            info.append((True, is_glossy(obj.material), is_glossy(obj.material) and obj.material.roughness == 0))
            base += len(v)
        self.scene = mi.load_dict({"type": "scene", **shapes}, parallel=False, optimize=False)
        self.vertices = np.concatenate(verts) if verts else np.zeros((0, 3), np.float32)   # (M, 3) cache points
        self.normals = np.concatenate(norms) if norms else np.zeros((0, 3), np.float32)    # (M, 3)
        self.rows = np.concatenate(rows) if rows else np.zeros(0, np.uint32)               # (M,) object index
        # (M,) index of each cache vertex among the distinct (position, normal) pairs, and (D,) one vertex of each:
        # irradiance and visibility are computed once per pair
        self.shared = np.concatenate(shared) if shared else np.zeros(0, np.int64)
        self.one_of = np.unique(self.shared, return_index=True)[1] if distinct else np.zeros(0, np.int64)
        self.pair = jit_array(mi.UInt32, self.shared.astype(np.uint32))
        self.tables = np.stack(tables).astype(np.float32)                                  # (objects, TABLE_NODES)
        self.reflects_diffuse = self.tables[:, -1] > 0                                     # (objects,)
        # Registry id of each loaded shape -> its first cache vertex and what its material does.
        ids = [int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(s))[0]) for s in self.scene.shapes()]
        order = {s.id(): i for i, s in enumerate(self.scene.shapes())}
        keys = list(shapes)
        table_base = np.zeros(max(ids) + 1, np.uint32)
        table_flags = np.zeros(max(ids) + 1, np.uint32)        # bit 0: cached, bit 1: glossy, bit 2: smooth,
        # bit 3: a glossy lobe rough enough to be read from the cache points towards a pinhole
        self.sids = np.zeros(len(keys), np.int64)               # registry id of each object's shape
        self.scene_index = np.zeros(len(keys), np.int64)        # its index in scene.shapes()
        self.pinhole_objects = np.asarray(pinhole, bool)
        for i, (key, b, (cached, glossy, smooth)) in enumerate(zip(keys, bases, info)):
            sid = ids[order[key]]
            self.sids[i] = sid
            table_base[sid] = b
            table_flags[sid] = int(cached) | (int(glossy) << 1) | (int(smooth) << 2) \
                | (int(bool(self.pinhole_objects[i])) << 3)
            self.scene_index[i] = order[key]
        self.flags_size = len(table_flags)
        self.base = jit_array(mi.UInt32, table_base)
        self.flags = jit_array(mi.UInt32, table_flags)
        self.glossy_objects = np.array([is_glossy(o.material) for o in self.objects], bool)
        self.keys = keys
        self.bases = bases

    def move(self, objects: list, moved: Sequence[int]) -> bool:
        """Move the objects ``moved`` (indices) to their poses in ``objects`` (the same objects, posed), in place:
        each is tessellated again, its vertex positions and normals are written into its loaded mesh, and the
        acceleration structure is rebuilt over them.

        Returns:
            True; False where that cannot be done (an emitter moved, or a moved object's vertex count or shared
            corners changed): then the caller builds the cache again.
        """
        mi = mitsuba()

        params = mi.traverse(self.scene)
        if any(objects[i].material.type == "emitter" for i in moved):
            return False
        for i in moved:
            cut = tessellation(objects[i], self.max_edge)
            v, n = cut.vertices, cut.normals
            end = self.bases[i + 1] if i + 1 < len(self.bases) else len(self.vertices)
            old = self.shared[self.bases[i]:end]
            if len(v) != end - self.bases[i] or not np.array_equal(cut.shared, old - (old.min() if len(old) else 0)):
                return False
            params[f"{self.keys[i]}.vertex_positions"] = mi.Float(v.ravel())
            params[f"{self.keys[i]}.vertex_normals"] = mi.Float(n.ravel())
            self.vertices[self.bases[i]:end] = v
            self.normals[self.bases[i]:end] = n
        params.update()
        self.objects = objects
        return True

    def arrangement(self) -> tuple[list, list[np.ndarray]]:
        """(objects, per object its cache vertices (P, 3)): the present arrangement, which later poses are compared
        with (:func:`~lftransfer.render.fast.interreflection.moved_together`)."""
        ends = [*self.bases[1:], len(self.vertices)]
        return list(self.objects), [self.vertices[b:e].copy() for b, e in zip(self.bases, ends)]


def interpolate(values, first, bary, active):
    """Barycentric interpolation of (M,) per-vertex ``values`` over the triangles starting at ``first``."""
    mi = mitsuba()
    import drjit as dr

    return (bary[0] * dr.gather(mi.Float, values, first, active)
            + bary[1] * dr.gather(mi.Float, values, first + 1, active)
            + bary[2] * dr.gather(mi.Float, values, first + 2, active))
