"""The fast path of the renderer: irradiance cached at the vertices of a fine tessellation.

Light field transfer is low-pass (one spatial sample per lenslet), and diffuse surfaces reflect irradiance, so
the expensive part of relighting, the sum over K lenslets with shadow rays, is done once per *cache vertex*
instead of once per ray: every synthetic object becomes a triangle mesh with edges of at most ``max_edge``, each
triangle with its own three vertices (so sharp edges stay sharp), and the irradiance at every vertex is computed
with the same lights as the exact path (area, point or prefiltered model, shadow rays). Rendering a light field
or a view image is then one ray cast per ray and a barycentric interpolation of the three vertex irradiances,
times albedo / pi.

When objects move (an animation frame, :meth:`CachedRenderer.update`), the moved objects' cache vertices are
re-tessellated in place (the acceleration structure is rebuilt over the new vertex positions) and every light's
irradiance is computed again (a moved object can shadow any other); while nothing moves, the irradiance of each
light is kept per light object, so a live loop that keeps its point light and swaps the captured light field
each frame relights only for the new light field.

What it keeps and what it drops against the exact path (:class:`~lftransfer.render.renderer.HalfSpaceRenderer`):
only diffuse materials and emitters (for glossy or metal objects use the exact path), one reflection inside the half-space
(interreflections between synthetic objects are dropped), and irradiance varies linearly across triangles of
size ``max_edge`` (6 mm by default, four times finer than a lenslet).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.render.integrator import Light
from lftransfer.render.renderer import HalfSpaceRenderer
from lftransfer.render.shapes import bsdf_dict, emitter_dict, object_keys, shape_dict

DEFAULT_MAX_EDGE = 0.006  # m


def supports(objects: Sequence) -> bool:
    """Whether the fast path renders these objects as the exact path would (all diffuse or emitters)."""
    return all(getattr(o.material, "type", "diffuse") in ("diffuse", "emitter") for o in objects)


def tessellate(obj, max_edge: float = DEFAULT_MAX_EDGE) -> tuple[np.ndarray, np.ndarray]:
    """World-space triangle soup of a scene object, refined to edges of at most ``max_edge``.

    Args:
        obj: ``lftransfer.scenes.ObjectConfig``.
        max_edge: longest triangle edge, metres.

    Returns:
        vertices (3F, 3) float32 (triangle f owns vertices 3f, 3f+1, 3f+2), normals (3F, 3) float32 unit
        (smooth on spheres, flat elsewhere).
    """
    import trimesh

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
    mesh.apply_transform(obj.to_world())
    faces = mesh.faces.reshape(-1)
    vertices = mesh.vertices[faces]
    if smooth:
        normals = mesh.vertex_normals[faces]
    else:
        normals = np.repeat(mesh.face_normals, 3, axis=0)
    return vertices.astype(np.float32), normals.astype(np.float32)


class CachedRenderer(HalfSpaceRenderer):
    """Renders diffuse objects from an irradiance cache at the vertices of a fine tessellation.

    The cache is recomputed whenever the list of lights changes (by identity), so rendering a light field and a
    view image with the same list relights once.

    Args:
        objects: scene objects (diffuse).
        max_edge: longest triangle edge of the cache, metres.

    Example:
        >>> r = CachedRenderer(scene.synthetic)                                   # doctest: +SKIP
        >>> lf = r.render_lightfield(array, lights, U=48, V=48, model="point")     # doctest: +SKIP
    """

    def __init__(self, objects: Sequence, *, max_edge: float = DEFAULT_MAX_EDGE) -> None:
        if not supports(objects):
            raise ValueError("the fast path renders diffuse materials and emitters only; use HalfSpaceRenderer")
        self.max_edge = float(max_edge)
        self.max_depth = 1
        self._build(list(objects))

    def _build(self, objects: list) -> None:
        mi = mitsuba()
        import drjit as dr

        max_edge = self.max_edge
        self.objects = objects
        shapes, verts, norms, albedo = {}, [], [], []
        base = 0
        bases = []
        for key, obj in zip(object_keys(self.objects), self.objects):
            if emitter_dict(obj.material) is not None:
                # an emitter reflects nothing (no cache vertices) and keeps its exact shape, so that emitter
                # sampling draws directions over what it subtends (a sphere's cone), not over facets
                shapes[key] = shape_dict(obj)
                verts.append(np.zeros((0, 3), np.float32))
                norms.append(np.zeros((0, 3), np.float32))
                albedo.append(np.zeros(3, np.float32))
                bases.append(base)
                continue
            v, n = tessellate(obj, max_edge)
            props = mi.Properties()
            props["bsdf"] = mi.load_dict(bsdf_dict(obj.material))
            mesh = mi.Mesh(key, len(v), len(v) // 3, props=props)
            params = mi.traverse(mesh)
            params["vertex_positions"] = mi.Float(v.ravel())
            params["faces"] = mi.UInt32(np.arange(len(v), dtype=np.uint32))
            params.update()
            shapes[key] = mesh
            verts.append(v)
            norms.append(n)
            albedo.append(np.asarray(getattr(obj.material, "albedo", [0.0, 0.0, 0.0]), np.float32))
            bases.append(base)
            base += len(v)
        self.scene = mi.load_dict({"type": "scene", **shapes}, parallel=False, optimize=False)
        self.vertices = np.concatenate(verts)                     # (M, 3) cache points
        self.normals = np.concatenate(norms)                      # (M, 3)
        # Registry id of each loaded shape -> its first cache vertex and its albedo / pi.
        ids = [int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(s))[0]) for s in self.scene.shapes()]
        order = {s.id(): i for i, s in enumerate(self.scene.shapes())}
        keys = list(shapes)
        table_base = np.zeros(max(ids) + 1, np.uint32)
        table_albedo = np.zeros((max(ids) + 1, 3), np.float32)
        for key, b, a in zip(keys, bases, albedo):
            sid = ids[order[key]]
            table_base[sid] = b
            table_albedo[sid] = a / np.pi
        self._base = mi.UInt32(table_base)
        self._albedo = mi.Float(table_albedo.ravel())
        self._keys = keys
        self._bases = bases
        self._irradiance = None
        self._lit_by: tuple | None = None
        self._per_light: dict[int, tuple[object, list[np.ndarray]]] = {}

    def update(self, objects: Sequence) -> bool:
        """Move to new poses of the same objects (an animation frame).

        Objects whose pose changed are re-tessellated; when their vertex count is unchanged (a rigid motion) the
        vertex positions are written into the loaded meshes and the acceleration structure is rebuilt over them,
        otherwise the whole cache is built again. Every light's irradiance is then stale.

        Args:
            objects: the objects, posed (``ObjectConfig.at(t)``), in the same order as before.

        Returns:
            Whether anything moved.
        """
        mi = mitsuba()

        objects = list(objects)
        if not supports(objects):
            raise ValueError("the fast path renders diffuse materials and emitters only; use HalfSpaceRenderer")
        if len(objects) != len(self.objects) or any(a.shape != b.shape or a.material != b.material
                                                    for a, b in zip(objects, self.objects)):
            self._build(objects)
            return True
        moved = [i for i, (a, b) in enumerate(zip(objects, self.objects)) if a.model_dump() != b.model_dump()]
        if not moved:
            return False
        params = mi.traverse(self.scene)
        if any(objects[i].material.type == "emitter" for i in moved):
            self._build(objects)
            return True
        for i in moved:
            v, n = tessellate(objects[i], self.max_edge)
            end = self._bases[i + 1] if i + 1 < len(self._bases) else len(self.vertices)
            if len(v) != end - self._bases[i]:
                self._build(objects)
                return True
            params[f"{self._keys[i]}.vertex_positions"] = mi.Float(v.ravel())
            self.vertices[self._bases[i]:end] = v
            self.normals[self._bases[i]:end] = n
        params.update()
        self.objects = objects
        self._per_light.clear()
        self._lit_by = None
        return True

    @property
    def cache_size(self) -> int:
        """Number of cache vertices M."""
        return len(self.vertices)

    def relight(self, lights: Sequence[Light], seed: int = 0) -> None:
        """Compute the irradiance at every cache vertex from ``lights`` (with shadow rays); a light object that
        lit the cache before, with nothing moved since, is not computed again."""
        mi = mitsuba()

        m = len(self.vertices)
        total = [np.zeros(m, np.float32) for _ in range(3)]
        kept = {}
        for light in lights:
            cached = self._per_light.get(id(light))
            e = cached[1] if cached is not None and cached[0] is light else self._irradiance_of(light, seed)
            kept[id(light)] = (light, e)
            for c in range(3):
                total[c] += e[c]
        self._per_light = kept
        self._irradiance = [mi.Float(t) for t in total]
        self._lit_by = tuple(lights)

    def _irradiance_of(self, light: Light, seed: int) -> list[np.ndarray]:
        """(3,) arrays (M,) of one light's irradiance at the cache vertices."""
        mi = mitsuba()
        import drjit as dr

        m = len(self.vertices)
        total = [np.zeros(m, np.float32) for _ in range(3)]
        # Shade only the vertices this light can reach (a light field through the array reaches those facing it
        # on its side of the plane).
        idx = np.flatnonzero(light.may_light(self.vertices, self.normals)) if hasattr(light, "may_light") \
            else np.arange(m)
        if len(idx) == 0:
            return total
        v, n = self.vertices[idx], self.normals[idx]
        si = dr.zeros(mi.SurfaceInteraction3f, len(idx))
        si.p = mi.Point3f(v[:, 0], v[:, 1], v[:, 2])
        si.n = mi.Normal3f(n[:, 0], n[:, 1], n[:, 2])
        si.sh_frame = mi.Frame3f(si.n)
        si.wi = mi.Vector3f(0, 0, 1)
        e = np.array(light.illuminate(self.scene, si, mi.Bool(True), seed=seed, irradiance=True), np.float32)
        for c in range(3):
            total[c][idx] = e[c]
        return total

    def render_rays(self, origins: np.ndarray, directions: np.ndarray, lights: Sequence[Light], *,
                    seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Radiance (N, 3), hit mask (N,) and distance (N,): one ray cast and a cache lookup per ray."""
        mi = mitsuba()
        import drjit as dr

        if self._lit_by is None or len(self._lit_by) != len(lights) or \
                any(a is not b for a, b in zip(self._lit_by, lights)):
            self.relight(lights, seed=seed)
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(directions, dtype=np.float32)
        rays = mi.Ray3f(mi.Point3f(o[:, 0], o[:, 1], o[:, 2]), mi.Vector3f(d[:, 0], d[:, 1], d[:, 2]))
        pi = self.scene.ray_intersect_preliminary(rays)
        hit = pi.is_valid()
        sid = dr.reinterpret_array(mi.UInt32, pi.shape)
        first = dr.gather(mi.UInt32, self._base, sid, hit) + pi.prim_index * 3
        b1, b2 = pi.prim_uv.x, pi.prim_uv.y
        b0 = 1.0 - b1 - b2
        emitted = mi.Color3f(0.0)
        seen = [light for light in lights if hasattr(light, "emitted")]
        if seen:    # emitting objects seen directly
            si = pi.compute_surface_interaction(rays, mi.RayFlags.All, hit)
            for light in seen:
                emitted += light.emitted(self.scene, si, hit)
        out = []
        for c in range(3):
            e = self._irradiance[c]
            value = (b0 * dr.gather(mi.Float, e, first, hit) + b1 * dr.gather(mi.Float, e, first + 1, hit)
                     + b2 * dr.gather(mi.Float, e, first + 2, hit))
            out.append(dr.select(hit, value * dr.gather(mi.Float, self._albedo, sid * 3 + c, hit) + emitted[c], 0.0))
        t = dr.select(hit, pi.t, dr.inf)
        dr.eval(out, t)
        radiance = np.stack([np.array(x, dtype=np.float32) for x in out], axis=1)
        t = np.array(t, dtype=np.float32)
        return radiance, np.isfinite(t), t
