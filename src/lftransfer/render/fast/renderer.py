"""The fast path's renderer (:class:`CachedRenderer`): the cache's geometry, its irradiance, the interreflection
gather and the glossy lobes composed into the renderer interface every renderer shares
(:class:`~lftransfer.render.base.RayRenderer`; module docs of :mod:`lftransfer.render.fast`)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.choices import DEFAULT_SPP
from lftransfer.render.base import RayRenderer, SampleMeans
from lftransfer.render.fast.burial import shade_under
from lftransfer.render.fast.glossy import (DEFAULT_LOBE_SAMPLES, DEFAULT_VIEW_LOBE_SAMPLES, GlossyLobes,
                                           pinhole_objects)
from lftransfer.render.fast.interreflection import GATHER_RAYS, Arrangement, exchanges_light
from lftransfer.render.fast.irradiance import IrradianceCache
from lftransfer.render.fast.materials import MATERIALS, bsdf_context, supports
from lftransfer.render.fast.mesh import CacheMesh, interpolate
from lftransfer.render.fast.rays import RaySets, group_means, rays_to_cast
from lftransfer.render.fast.tessellation import DEFAULT_MAX_EDGE
from lftransfer.render.integrator import Light
from lftransfer.render.lights import jit_array, to_numpy


class CachedRenderer(RayRenderer):
    """Renders objects from a diffuse irradiance cache at the vertices of a fine tessellation, with glossy lobes
    evaluated per ray (module docs).

    The cache is recomputed whenever the list of lights changes (by identity), so rendering a light field and a
    view image with the same list relights once.

    Args:
        objects: scene objects (diffuse, glossy, metal or emitter; albedo textures on rectangles, boxes, spheres).
        max_edge: longest triangle edge of the cache, metres.
        lobe_samples: directions drawn per ray from a glossy lobe of roughness up to ``LOBE_ROUGHNESS`` for a
            light field of the area model (rounded to a square number; rougher lobes take more,
            :func:`lobe_strata`; a smooth lobe takes its one mirror direction).
        view_lobe_samples: the same for the rays of a view render (:meth:`render_view`).
        glossy: evaluate the glossy lobes (False: the diffuse cache alone, a control for tests).
        max_depth: surface interactions per path, as the exact path counts them: 1 renders the lights' direct
            light only; each one more adds a round of the interreflection gather (``gathers`` = max_depth - 1)
            where the objects light each other.
        gather_rays: directions of the interreflection gather per cache point.

    Example:
        >>> r = CachedRenderer(scene.synthetic)                                   # doctest: +SKIP
        >>> lf = r.render_lightfield(array, lights, U=48, V=48, model="point")     # doctest: +SKIP
    """

    kind = "fast"

    def __init__(self, objects: Sequence, *, max_edge: float = DEFAULT_MAX_EDGE,
                 lobe_samples: int = DEFAULT_LOBE_SAMPLES, view_lobe_samples: int = DEFAULT_VIEW_LOBE_SAMPLES,
                 glossy: bool = True, max_depth: int = 1, gather_rays: int = GATHER_RAYS, windows=None) -> None:
        if not supports(objects):
            raise ValueError(f"the fast path renders the materials {MATERIALS} only; use the exact path")
        if lobe_samples < 1 or view_lobe_samples < 1:
            raise ValueError(f"lobe_samples and view_lobe_samples must be >= 1, got {lobe_samples} and "
                             f"{view_lobe_samples}")
        if max_depth < 1 or gather_rays < 1:
            raise ValueError(f"max_depth and gather_rays must be >= 1, got {max_depth} and {gather_rays}")
        self.max_edge = float(max_edge)
        self.lobe_samples = int(lobe_samples)
        self.view_lobe_samples = int(view_lobe_samples)
        self.glossy = bool(glossy)
        self.max_depth = int(max_depth)
        self.gathers = self.max_depth - 1
        self.gather_rays = int(gather_rays)
        self.windows = windows
        self._ray_sets = RaySets()
        self._build(list(objects))

    def _build(self, objects: list) -> None:
        """Build the cache for ``objects``: its geometry, and an empty irradiance cache, gather and lobes over it."""
        self.mesh = CacheMesh(objects, self.max_edge, pinhole_objects(objects))
        self.arrangement = Arrangement(self.mesh, self.gather_rays, self.windows)
        self.irradiance = IrradianceCache(self.mesh, self.arrangement, self.gathers)
        self.lobes = GlossyLobes(self.mesh, self.arrangement, self.irradiance, self.gathers, self.lobe_samples)
        self._any_glossy = self.glossy and bool(self.mesh.glossy_objects.any())
        self._any_pinhole = self.glossy and bool(self.mesh.pinhole_objects.any())

    @property
    def objects(self) -> list:
        """The scene objects, posed."""
        return self.mesh.objects

    @property
    def scene(self):
        """The Mitsuba scene of the cache meshes and the emitters."""
        return self.mesh.scene

    @property
    def vertices(self) -> np.ndarray:
        """(M, 3) float32 cache points."""
        return self.mesh.vertices

    @property
    def normals(self) -> np.ndarray:
        """(M, 3) float32 their unit normals."""
        return self.mesh.normals

    def update(self, objects: Sequence) -> bool:
        """Move to new poses of the same objects (an animation frame).

        Objects whose pose changed are re-tessellated; when their vertex count is unchanged (a rigid motion) the
        vertex positions and normals are written into the loaded meshes and the acceleration structure is rebuilt
        over them, otherwise the whole cache is built again. Every light's irradiance is then stale.

        Args:
            objects: the objects, posed (``ObjectConfig.at(t)``), in the same order as before.

        Returns:
            Whether anything moved.
        """
        objects = list(objects)
        if not supports(objects):
            raise ValueError(f"the fast path renders the materials {MATERIALS} only; use the exact path")
        if len(objects) != len(self.objects) or any(a.shape != b.shape or a.material != b.material
                                                    for a, b in zip(objects, self.objects)):
            self._build(objects)
            return True
        moved = [i for i, (a, b) in enumerate(zip(objects, self.objects)) if a.model_dump() != b.model_dump()]
        if not moved:
            return False
        if not self.mesh.move(objects, moved):
            self._build(objects)
            return True
        self.arrangement.follow()
        self.lobes.forget()
        self.irradiance.forget()
        return True

    @property
    def exchanges(self) -> bool:
        """Whether this renderer's surfaces light each other (:func:`exchanges_light`)."""
        return exchanges_light(self.objects)

    def render_view(self, sensor, width: int, height: int, lights: Sequence[Light], *, spp: int = DEFAULT_SPP,
                    seed: int = 0):
        """:meth:`RayRenderer.render_view`, its glossy lobes sampled with ``view_lobe_samples`` directions
        per ray."""
        with self.lobes.drawing(self.view_lobe_samples):
            return super().render_view(sensor, width, height, lights, spp=spp, seed=seed)

    @property
    def cache_size(self) -> int:
        """Number of cache vertices M."""
        return len(self.vertices)

    def relight(self, lights: Sequence[Light], seed: int = 0) -> None:
        """Compute the diffuse irradiance at every cache vertex from ``lights`` (with shadow rays); a light
        object that lit the cache before, with nothing moved since, is not computed again."""
        self.irradiance.relight(lights, seed=seed)

    def _hits(self, origins: np.ndarray, directions: np.ndarray, lights: Sequence[Light], seed: int
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One ray cast per ray and the cache lookup (and glossy lobe) at the hits only: (H,) int64 indices of the
        rays that hit, (H, 3) float32 their radiance and (H,) float32 their hit distances.

        Of a constant ray set (the primary rays) only the tiles whose cone meets an object's bounding sphere are
        cast (:func:`~lftransfer.render.fast.rays.rays_to_cast`, :mod:`lftransfer.render.culling`: the rays left
        out miss, so the result is the same)."""
        mi = mitsuba()
        import drjit as dr

        if not self.irradiance.lit_by(lights):
            self.relight(lights, seed=seed)
        rays = self.jit_rays(origins, directions)
        ray_set = self._ray_sets.find(origins, directions)
        cast = rays_to_cast(ray_set, origins, directions, self.scene)   # indices of the rays cast (None: all)
        if cast is not None:
            if ray_set.cast_rays is not None and ray_set.cast_rays[0] is cast:     # culled as at the last render
                rays = ray_set.cast_rays[1]
            else:
                rays = dr.gather(mi.Ray3f, rays, jit_array(mi.UInt32, cast.astype(np.uint32)))
                dr.eval(rays)                # one kernel (the intersection would gather each field in its own)
                ray_set.cast_rays = (cast, rays)
        pi = self.scene.ray_intersect_preliminary(rays)
        dr.eval(pi)          # every field in one kernel (read apart, each would intersect again)
        t = np.array(pi.t, dtype=np.float32)
        local = np.flatnonzero(np.isfinite(t))
        idx = local if cast is None else cast[local]
        if not len(idx):
            return idx, np.zeros((0, 3), np.float32), np.zeros(0, np.float32)
        index = jit_array(mi.UInt32, local.astype(np.uint32))
        pi = dr.gather(mi.PreliminaryIntersection3f, pi, index)
        rays = dr.gather(mi.Ray3f, rays, index)
        pinhole = ray_set.centre() if ray_set is not None and self._any_pinhole else None
        return idx, to_numpy(self._shade(rays, pi, lights, seed, pinhole)), t[local]

    def render_rays(self, origins: np.ndarray, directions: np.ndarray, lights: Sequence[Light], *,
                    seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Radiance (N, 3), hit mask (N,) and distance (N,): one ray cast and a cache lookup per ray (and the
        glossy lobe at rays that meet a glossy object)."""
        idx, colour, t_hit = self._hits(origins, directions, lights, seed)
        radiance = np.zeros((len(origins), 3), np.float32)
        radiance[idx] = colour
        t = np.full(len(origins), np.inf, np.float32)
        t[idx] = t_hit
        return radiance, np.isfinite(t), t

    def render_samples(self, origins: np.ndarray, directions: np.ndarray, lights: Sequence[Light], spp: int, *,
                       seed: int = 0) -> SampleMeans:
        """:meth:`RayRenderer.render_samples`, summed over the rays that hit only (a view's objects cover a
        few per cent of its rays, so full-size passes over every ray's radiance were most of a view render)."""
        if spp == 1:                                 # one ray per group (the projection prefilter's rays)
            radiance, hit, t = self.render_rays(origins, directions, lights, seed=seed)
            return SampleMeans(radiance=radiance, coverage=hit.astype(np.float32), depth=t)
        idx, colour, t_hit = self._hits(origins, directions, lights, seed)
        return group_means(idx, colour, t_hit, len(origins) // spp, spp)

    def _shade(self, rays, pi, lights: Sequence[Light], seed: int, pinhole: np.ndarray | None = None):
        """Radiance (mi.Color3f, (N,)) leaving the hits ``pi`` of ``rays`` (all valid) back along the rays.

        ``pinhole``: the one origin (3,) of every ray (a view camera), or None; then glossy lobes rough enough
        (:data:`PINHOLE_ROUGHNESS`) are read from their radiance towards that point at the cache points
        (:meth:`GlossyLobes.pinhole`), interpolated like the irradiance, instead of being sampled at every ray (not
        under a light field of the point or prefiltered model, whose point lenslets make sharp highlights)."""
        mi = mitsuba()
        import drjit as dr

        si = pi.compute_surface_interaction(rays, mi.RayFlags.All)
        sid = dr.reinterpret_array(mi.UInt32, pi.shape)
        flags = dr.gather(mi.UInt32, self.mesh.flags, sid)
        cached = (flags & 1) != 0

        def at(index):                       # the hits ``index``, computed again there (not gathered field by field)
            return dr.gather(mi.PreliminaryIntersection3f, pi, index).compute_surface_interaction(
                dr.gather(mi.Ray3f, rays, index), mi.RayFlags.All)

        first = dr.gather(mi.UInt32, self.mesh.base, sid, cached) + pi.prim_index * 3
        b1, b2 = pi.prim_uv.x, pi.prim_uv.y
        bary = (1.0 - b1 - b2, b1, b2)
        e = [interpolate(x, first, bary, cached) for x in self.irradiance.values]
        bsdf = si.bsdf()
        # the diffuse lobe towards the normal: albedo(uv) / pi for a diffuse material, A(uv) t(cos_i) t(1) for a
        # glossy one (module docs)
        f = bsdf.eval(bsdf_context("diffuse"), si, mi.Vector3f(0.0, 0.0, 1.0), cached)
        out = dr.select(cached, mi.Color3f(e[0], e[1], e[2]) * f, 0.0)
        for light in lights:
            if hasattr(light, "emitted"):     # emitting objects seen directly
                out += light.emitted(self.scene, si, mi.Bool(True))
        if self._any_glossy:
            glossy = cached & ((flags & 2) != 0)
            # a light field of point lenslets makes sharp highlights (one per lenslet): those stay per ray
            if pinhole is not None and self._any_pinhole and all(getattr(x, "model", "area") == "area"
                                                                 for x in lights):
                at_points = glossy & ((flags & 8) != 0)
                g = [interpolate(x, first, bary, at_points) for x in self.lobes.pinhole(pinhole, lights, seed)]
                out += dr.select(at_points, mi.Color3f(g[0], g[1], g[2]), 0.0)
                glossy &= ~at_points
            out += self.lobes.evaluate(si, glossy, sid, flags, first, bary, lights, seed, at)
        return shade_under(self.mesh, self.arrangement.burial(), at, first, cached, out, lights, seed)
