"""The glossy and metal lobes of the fast path, evaluated per ray (:class:`GlossyLobes`): point lights and emitters
by their own sampling; a light field of the area model by directions drawn from the lobe (stratified, multi-
jittered), each read where it meets the array plane, combined with the exact path's lenslet sum by multiple
importance sampling where that pays; occlusion from the lenslet visibility cache; the diffuse light of the other
cached surfaces through the lobe's directions; and in a view, rough lobes read once per cache point towards the
camera's centre."""

from __future__ import annotations

from contextlib import contextmanager
from typing import Sequence

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.render.fast.interreflection import Arrangement, exchanges_light
from lftransfer.render.fast.irradiance import IrradianceCache
from lftransfer.render.fast.materials import bsdf_context, is_glossy
from lftransfer.render.fast.mesh import CacheMesh, interpolate
from lftransfer.render.fast.visibility import LensletVisibility
from lftransfer.render.integrator import Light
from lftransfer.render.lights import jit_array, to_numpy

DEFAULT_LOBE_SAMPLES = 16
DEFAULT_VIEW_LOBE_SAMPLES = 36   # ... per view ray: a view has few rays, and its pixels are what one sees
LOBE_ROUGHNESS = 0.15       # lobes up to this roughness take lobe_samples directions; rougher ones more
PINHOLE_ROUGHNESS = 0.15    # glossy lobes at least this rough are read from the cache points in a view render
PINHOLE_SAMPLES = 4         # ... with this many times the lobe directions of a ray (the points are few)


def lobe_strata(roughness: float, lobe_samples: int = DEFAULT_LOBE_SAMPLES) -> int:
    """Strata per axis S of the directions drawn from a glossy lobe of GGX ``roughness`` (S * S per ray).

    S0 = round(sqrt(lobe_samples)) up to roughness ``LOBE_ROUGHNESS``; a rougher lobe spans a solid angle
    growing as roughness^2 and takes S = ceil(S0 * roughness / LOBE_ROUGHNESS), at most 4 S0, so that its
    noise stays near the exact path's; a smooth lobe (roughness 0) has its one mirror direction (S = 1).
    """
    if roughness <= 0:
        return 1
    side0 = max(1, int(round(np.sqrt(lobe_samples))))
    return int(min(4 * side0, max(side0, np.ceil(side0 * roughness / LOBE_ROUGHNESS - 1e-9))))


def pinhole_objects(objects: Sequence) -> np.ndarray:
    """(objects,) bool: the glossy and metal objects rough enough (:data:`PINHOLE_ROUGHNESS`) that a view render
    reads their lobes from the cache points (:meth:`GlossyLobes.pinhole`)."""
    return np.array([is_glossy(o.material) and o.material.roughness >= PINHOLE_ROUGHNESS for o in objects], bool)


def _lobe_direction(bsdf, ctx, si, rng, j, strata, side, active, shift):
    """Direction j of ``strata`` x ``strata`` stratified directions drawn from the lobe ``ctx`` enables (Mitsuba's
    own sampling; ``side`` is ``strata`` as a float): (BSDF sample, its weight, the lanes where it carries light).

    The strata are also split along each axis into strata^2 fine bins that the directions fill once each
    (correlated multi-jittered sampling, Kensler 2013): stratum (i, k) takes fine bin (k + a) mod strata of its
    column and (i + b) mod strata of its row, ``shift`` = (a, b) drawn once per ray (mi.UInt32 each), so every
    direction stays uniform in its stratum. Mitsuba maps the sample square onto a disk (concentric map) whose
    rim is the lobe's tail, and a GGX lobe's tails are long (at roughness 0.08 a tenth of its microfacet normals
    lie more than 13 degrees off, where the reflected direction leaves the lenslets' window and the light field
    ends): along each axis the fine bins place strata^2 directions across that edge instead of strata."""
    mi = mitsuba()
    import drjit as dr

    r1, r2, r3 = rng.next_float32(), rng.next_float32(), rng.next_float32()
    i, k = j % strata, j // strata
    fx, fy = (k + shift[0]) % strata, (i + shift[1]) % strata
    sample = mi.Point2f((mi.Float(i) + (mi.Float(fx) + r2) / side) / side,
                        (mi.Float(k) + (mi.Float(fy) + r3) / side) / side)
    bs, weight = bsdf.sample(ctx, si, r1, sample, active)
    return bs, weight, active & dr.any(weight != 0.0)


def _shifts(rng, strata):
    """(a, b): the per-ray offsets of :func:`_lobe_direction`'s fine bins, mi.UInt32 in [0, strata)."""
    return rng.next_uint32() % strata, rng.next_uint32() % strata


class GlossyLobes:
    """The glossy and metal lobes' light at shading points of the cache ``mesh`` (:meth:`evaluate`; module docs of
    :mod:`lftransfer.render.fast`).

    Args:
        mesh: the cache's geometry.
        arrangement: its interreflection gather (the other surfaces a lobe reads) and buried points.
        irradiance: the irradiance cache (the other surfaces' diffuse light).
        gathers: rounds of the interreflection gather (with none, a lobe reads no other surface).
        lobe_samples: directions drawn per ray from a lobe of roughness up to ``LOBE_ROUGHNESS``
            (:func:`lobe_strata`).

    Attributes:
        samples: the lobe directions of the render under way (``lobe_samples`` outside :meth:`drawing`).
        visibility: the lenslet visibility cache (:class:`~lftransfer.render.fast.visibility.LensletVisibility`).
    """

    def __init__(self, mesh: CacheMesh, arrangement: Arrangement, irradiance: IrradianceCache, gathers: int,
                 lobe_samples: int) -> None:
        self.mesh = mesh
        self.arrangement = arrangement
        self.irradiance = irradiance
        self.gathers = int(gathers)
        self.lobe_samples = int(lobe_samples)
        self.samples = self.lobe_samples
        self.visibility = LensletVisibility(mesh, arrangement, gathers)
        self._pinhole_memo = None

    def forget(self) -> None:
        """The objects moved: the visibility tables and the lobes read towards a pinhole are stale."""
        self.visibility.forget()
        self._pinhole_memo = None

    @contextmanager
    def drawing(self, count: int):
        """Draw ``count`` lobe directions per ray (instead of ``lobe_samples``) inside the block."""
        kept, self.samples = self.samples, int(count)
        try:
            yield
        finally:
            self.samples = kept

    def evaluate(self, si, glossy, sid, flags, first, bary, lights: Sequence[Light], seed: int, at=None):
        """The glossy and metal lobes' light at the shading points ``si`` where ``glossy`` (mi.Color3f): point lights
        and emitters by their own sampling, a light field by :meth:`_lobe` (and the lenslet sum where it pays), the
        other cached surfaces by :meth:`_neighbours`; ``first`` and ``bary`` place each point in its cache
        triangle (for the visibility and gather tables); ``at(index)``: the shading points ``index`` (by default
        gathered from ``si``)."""
        mi = mitsuba()
        import drjit as dr

        if at is None:
            def at(index):
                return dr.gather(mi.SurfaceInteraction3f, si, index)
        out = mi.Color3f(0.0)
        smooth = (flags & 4) != 0
        ctx = bsdf_context("glossy")
        # the distinct cache point of each corner (the visibility tables hold one row per point)
        corners = [dr.gather(mi.UInt32, self.mesh.pair, first + c, glossy) for c in range(3)]
        b0, b1, b2 = bary
        for light in lights:
            if not hasattr(light, "reflect"):       # point lights, emitters: their own sampling
                out += light.illuminate(self.mesh.scene, si, glossy, seed=seed, ctx=ctx)
                continue
            table, varying = self.visibility.of(light)
            K = light.K

            def seen(k, table=table, K=K):
                ok = glossy & (k < K)
                return (b0 * dr.gather(mi.Float, table, corners[0] * K + k, ok)
                        + b1 * dr.gather(mi.Float, table, corners[1] * K + k, ok)
                        + b2 * dr.gather(mi.Float, table, corners[2] * K + k, ok))

            if light.model != "area":         # lenslets are points: summed, as the exact path does
                out += light.reflect(si, glossy & ~smooth, ctx, seen, seed=seed)
                continue
            strata, summed, any_summed = self._strategies(light)
            side = dr.gather(mi.UInt32, strata, sid, glossy)
            by_lenslet = glossy & (dr.gather(mi.UInt32, summed, sid, glossy) != 0)
            if any_summed:
                out += light.reflect(si, by_lenslet, ctx, seen, self._base_samples(), seed=seed)
            cast = None if varying is None else glossy & (dr.gather(mi.UInt32, varying, first // 3, glossy) != 0)
            out += self._lobe(si, glossy if cast is None else glossy & ~cast, by_lenslet, side, light, seen, seed)
            if cast is not None:
                out = self._cast(at, cast, by_lenslet, side, light, seed, out)
        if self.gathers and exchanges_light(self.mesh.objects):       # the other objects' diffuse light in the lobe
            self.arrangement.gather()
            sees = interpolate(self.arrangement.sees, first, bary, glossy)
            out += self._neighbours(si, glossy & (sees > 0.0), seed)
        return out

    def pinhole(self, origin: np.ndarray, lights: Sequence[Light], seed: int) -> list:
        """(3,) mi.Float (M,): the glossy lobes' radiance from every cache point of an object rough enough
        (:data:`PINHOLE_ROUGHNESS`) towards the point ``origin`` (a view camera's centre), zero elsewhere and at
        points facing away; computed by :meth:`evaluate` once per distinct cache point and kept while the lights,
        the seed and the objects stay."""
        mi = mitsuba()
        import drjit as dr

        key = (tuple(np.round(np.asarray(origin, np.float64), 9)), seed)
        kept = self._pinhole_memo
        if kept is not None and kept[0] == key and len(kept[1]) == len(lights) \
                and all(a is b for a, b in zip(kept[1], lights)):
            return kept[2]
        one = self.mesh.one_of
        m = len(self.mesh.vertices)
        rows = self.mesh.rows[one]
        x, n = self.mesh.vertices[one].astype(np.float64), self.mesh.normals[one].astype(np.float64)
        towards = np.asarray(origin, np.float64)[None, :] - x
        want = self.mesh.pinhole_objects[rows] & (np.einsum("dk,dk->d", towards, n) > 0) if m else np.zeros(0, bool)
        per_pair = np.zeros((len(one), 3), np.float32)
        if want.any():
            v = one[want]                                        # a cache vertex of each point
            w = towards[want] / np.linalg.norm(towards[want], axis=1, keepdims=True)
            si = dr.zeros(mi.SurfaceInteraction3f, len(v))
            si.p = mi.Point3f(*(jit_array(mi.Float, x[want][:, i]) for i in range(3)))
            si.n = mi.Normal3f(*(jit_array(mi.Float, n[want][:, i]) for i in range(3)))
            si.sh_frame = mi.Frame3f(si.n)
            si.wi = si.sh_frame.to_local(mi.Vector3f(*(jit_array(mi.Float, w[:, i]) for i in range(3))))
            si.shape = dr.gather(mi.ShapePtr, self.mesh.scene.shapes_dr(),
                                 jit_array(mi.UInt32, self.mesh.scene_index[rows[want]].astype(np.uint32)))
            sid = jit_array(mi.UInt32, self.mesh.sids[rows[want]].astype(np.uint32))
            flags = dr.gather(mi.UInt32, self.mesh.flags, sid)
            first = jit_array(mi.UInt32, (v - v % 3).astype(np.uint32))
            corner = v % 3
            bary = tuple(jit_array(mi.Float, (corner == c).astype(np.float32)) for c in range(3))
            with self.drawing(self.lobe_samples * PINHOLE_SAMPLES):
                per_pair[want] = to_numpy(self.evaluate(si, mi.Bool(True), sid, flags, first, bary, lights, seed))
        values = [jit_array(mi.Float, per_pair[self.mesh.shared, c]) for c in range(3)]
        self._pinhole_memo = (key, tuple(lights), values)
        return values

    def _neighbours(self, si, active, seed: int):
        """The diffuse light of the other cached surfaces that a glossy lobe reflects (mi.Color3f, (N,)):
        ``lobe_samples`` directions drawn from the lobe (stratified), each cast against the scene; a direction that
        meets a cached surface reads its diffuse radiance (irradiance cache times its diffuse lobe), one that meets
        nothing or the array is the light field's share (:meth:`_lobe`)."""
        mi = mitsuba()
        import drjit as dr

        n = dr.width(si.p)
        ctx = bsdf_context("glossy")
        diffuse = bsdf_context("diffuse")
        bsdf = si.bsdf()
        side = int(round(np.sqrt(self._base_samples())))
        count = side * side
        rng = mi.PCG32(n, dr.opaque(mi.UInt64, seed * 1000003 + 29), dr.arange(mi.UInt64, n))
        shift = _shifts(rng, mi.UInt32(side))
        irradiance = self.irradiance.values

        def cond(j, rng, acc):
            return active & (j < count)

        def body(j, rng, acc):
            bs, weight, ok = _lobe_direction(bsdf, ctx, si, rng, j, side, float(side), active, shift)
            ray = si.spawn_ray(si.to_world(bs.wo))
            pi = self.mesh.scene.ray_intersect_preliminary(ray, active=ok)
            sid = dr.reinterpret_array(mi.UInt32, pi.shape)
            met = ok & pi.is_valid()
            met &= (dr.gather(mi.UInt32, self.mesh.flags, sid, met) & 1) != 0
            hit = pi.compute_surface_interaction(ray, mi.RayFlags.All, met)
            first = dr.gather(mi.UInt32, self.mesh.base, sid, met) + pi.prim_index * 3
            bary = (1.0 - pi.prim_uv.x - pi.prim_uv.y, pi.prim_uv.x, pi.prim_uv.y)
            e = [interpolate(x, first, bary, met) for x in irradiance]
            f = hit.bsdf().eval(diffuse, hit, mi.Vector3f(0.0, 0.0, 1.0), met)
            acc += dr.select(met, weight * f * mi.Color3f(e[0], e[1], e[2]), 0.0)
            return j + 1, rng, acc

        _, _, acc = dr.while_loop((mi.UInt32(0), rng, mi.Color3f(0.0)), cond, body)
        return dr.select(active, acc / count, 0.0)

    def _base_samples(self) -> int:
        side0 = max(1, int(round(np.sqrt(self.samples))))
        return side0 * side0

    def _strategies(self, light):
        """Per shape registry id: the strata per axis of its glossy lobe's directions (mi.UInt32), and whether
        its lobe also sums the lenslets (mi.UInt32, 0 / 1): when the K_active * M aperture points of this light
        cost no more than the directions its roughness asks for (:func:`lobe_strata`), the lenslet sum and
        ``lobe_samples`` directions are combined by multiple importance sampling; otherwise the directions alone
        estimate the lobe. Also whether any shape sums the lenslets."""
        mi = mitsuba()
        cost = len(light.active_lenslets) * light.M
        strata = np.zeros(self.mesh.flags_size, np.uint32)
        summed = np.zeros(self.mesh.flags_size, np.uint32)
        side0 = int(round(np.sqrt(self._base_samples())))
        for sid, obj in zip(self.mesh.sids, self.mesh.objects):
            if not is_glossy(obj.material):
                continue
            side = lobe_strata(obj.material.roughness, self.samples)
            if obj.material.roughness > 0 and cost <= side * side:
                strata[sid], summed[sid] = side0, 1
            else:
                strata[sid] = side
        return jit_array(mi.UInt32, strata), jit_array(mi.UInt32, summed), bool(summed.any())

    def _cast(self, at, cast, summed, strata, light, seed: int, out):
        """``out`` (mi.Color3f) plus :meth:`_lobe` at the lanes ``cast`` (compacted: they are few; ``at(index)`` is
        the surface interaction of lanes ``index``), each of whose directions is cast against the scene instead of
        reading the cache's visibility."""
        mi = mitsuba()
        import drjit as dr

        index = dr.compress(cast)
        if dr.width(index) == 0:
            return out
        value = self._lobe(at(index), mi.Bool(True), dr.gather(mi.Bool, summed, index),
                           dr.gather(mi.UInt32, strata, index), light, None, seed)
        dr.eval(out, value)                  # one kernel each (scattered channel by channel, each would recompute)
        dr.scatter_add(out, value, index)
        return out

    def _lobe(self, si, active, summed, strata, light, seen, seed: int):
        """The directions drawn from a glossy lobe: its light from a light field of the area model
        (mi.Color3f, (N,)).

        ``strata`` ** 2 directions (per shading point) drawn from the lobe (Mitsuba's visible-normal sampling,
        stratified), each read where it meets the array plane (:meth:`LightFieldLight.incident`), occluded as the
        cache says (``seen(k)``, the fraction of the lenslet k it meets that the shading point sees). Where
        ``summed``, the lenslet sum of :meth:`LightFieldLight.reflect` estimates the same light, and each
        direction takes the balance heuristic's share n p_b / (n p_b + p_l); a smooth lobe (one direction) and
        the others take it all. With ``seen`` None each direction is cast against the scene instead.
        """
        mi = mitsuba()
        import drjit as dr

        n = dr.width(si.p)
        ctx = bsdf_context("glossy")
        bsdf = si.bsdf()
        rng = mi.PCG32(n, dr.opaque(mi.UInt64, seed * 1000003 + 17), dr.arange(mi.UInt64, n))
        strata = dr.maximum(strata, 1)            # no integer division by zero in inactive lanes
        count = strata * strata
        side = mi.Float(strata)
        n_f = mi.Float(count)

        shift = _shifts(rng, strata)

        def visibility(k, w, ok):
            if seen is None:
                return dr.select(self.mesh.scene.ray_test(si.spawn_ray(w), ok), 0.0, 1.0)
            return seen(k)

        def cond(j, rng, acc):
            return active & (j < count)

        def body(j, rng, acc):
            bs, weight, ok = _lobe_direction(bsdf, ctx, si, rng, j, strata, side, active, shift)
            w = si.to_world(bs.wo)
            radiance, k, p_l = light.incident(si.p, w, ok)
            mis = dr.select(summed, n_f * bs.pdf / dr.maximum(n_f * bs.pdf + p_l, 1e-30), 1.0)
            acc += dr.select(ok, weight * radiance * (visibility(k, w, ok) * mis), 0.0)
            return j + 1, rng, acc

        _, _, acc = dr.while_loop((mi.UInt32(0), rng, mi.Color3f(0.0)), cond, body)
        return dr.select(active, acc / n_f, 0.0)
