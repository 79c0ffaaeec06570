"""The irradiance cache: the diffuse irradiance at the cache vertices, computed per light with the same lights as the
exact path (shadow rays) once per distinct (position, normal) pair, kept per light object while nothing moves, with
the interreflection gather's rounds added and the buried points filled (:class:`IrradianceCache`)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.render.fast.interreflection import Arrangement, exchanges_light
from lftransfer.render.fast.materials import TABLE_NODES
from lftransfer.render.fast.mesh import CacheMesh
from lftransfer.render.integrator import Light
from lftransfer.render.lights import jit_array


class IrradianceCache:
    """The diffuse irradiance at the vertices of the cache ``mesh``, each direction weighted by its cosine times the
    vertex's material's :func:`~lftransfer.render.fast.materials.diffuse_lobe_table`.

    Args:
        mesh: the cache's geometry.
        arrangement: its interreflection gather and buried points.
        gathers: rounds of the interreflection gather added (where the objects light each other).

    Attributes:
        values: (3,) mi.Float (M,), the irradiance of the lights that lit the cache last (None before).
    """

    def __init__(self, mesh: CacheMesh, arrangement: Arrangement, gathers: int) -> None:
        self.mesh = mesh
        self.arrangement = arrangement
        self.gathers = int(gathers)
        self.values: list | None = None
        self._lit_by: tuple | None = None
        self._per_light: dict[int, tuple[object, list[np.ndarray]]] = {}

    def lit_by(self, lights: Sequence[Light]) -> bool:
        """Whether the cache holds the light of exactly these light objects (by identity)."""
        return not (self._lit_by is None or len(self._lit_by) != len(lights)
                    or any(a is not b for a, b in zip(self._lit_by, lights)))

    def forget(self) -> None:
        """The objects moved: every light's irradiance is stale."""
        self._per_light.clear()
        self._lit_by = None

    def relight(self, lights: Sequence[Light], seed: int = 0) -> None:
        """Compute the diffuse irradiance at every cache vertex from ``lights`` (with shadow rays); a light
        object that lit the cache before, with nothing moved since, is not computed again."""
        mi = mitsuba()

        mesh = self.mesh
        m = len(mesh.vertices)
        total = [np.zeros(m, np.float32) for _ in range(3)]
        kept = {}
        for light in lights:
            cached = self._per_light.get(id(light))
            e = cached[1] if cached is not None and cached[0] is light else self.irradiance_of(light, seed)
            kept[id(light)] = (light, e)
            for c in range(3):
                total[c] += e[c]
        self._per_light = kept
        if self.gathers and exchanges_light(mesh.objects):
            gather = self.arrangement.gather()
            bounce = total
            for _ in range(self.gathers):
                bounce = [gather.bounce(bounce[c], c, mesh.shared) for c in range(3)]
                total = [t + b for t, b in zip(total, bounce)]
        burial = self.arrangement.burial()
        if burial is not None:
            total = [np.asarray(burial.fill @ t[mesh.one_of], np.float32)[mesh.shared] for t in total]
        self.values = [jit_array(mi.Float, t) for t in total]
        self._lit_by = tuple(lights)

    def irradiance_of(self, light: Light, seed: int) -> list[np.ndarray]:
        """(3,) arrays (M,) of one light's diffuse irradiance at the cache vertices: each direction weighted by
        its cosine times the vertex's material's :func:`diffuse_lobe_table` (zero for metals). It is computed once
        per distinct (position, normal) pair and read back at every cache vertex of the pair."""
        mi = mitsuba()
        import drjit as dr

        mesh = self.mesh
        m = len(mesh.vertices)
        total = [np.zeros(m, np.float32) for _ in range(3)]
        one = mesh.one_of                      # (D,) a cache vertex of every distinct pair
        # Shade only the vertices with a diffuse lobe that this light can reach (a light field through the array
        # reaches those facing it on its side of the plane).
        wanted = mesh.reflects_diffuse[mesh.rows[one]] if m else np.zeros(0, bool)
        if hasattr(light, "may_light"):
            wanted &= light.may_light(mesh.vertices[one], mesh.normals[one])
        idx = one[wanted]
        if len(idx) == 0:
            return total
        v, n = mesh.vertices[idx], mesh.normals[idx]
        si = dr.zeros(mi.SurfaceInteraction3f, len(idx))
        si.p = mi.Point3f(*(jit_array(mi.Float, v[:, i]) for i in range(3)))
        si.n = mi.Normal3f(*(jit_array(mi.Float, n[:, i]) for i in range(3)))
        si.sh_frame = mi.Frame3f(si.n)
        si.wi = mi.Vector3f(0, 0, 1)
        weight = self.cosine_weight(mesh.rows[idx])
        e = np.array(light.illuminate(mesh.scene, si, mi.Bool(True), seed=seed, irradiance=weight), np.float32)
        per_pair = np.zeros((3, len(one)), np.float32)
        per_pair[:, wanted] = e
        return [per_pair[c][mesh.shared] for c in range(3)]

    def cosine_weight(self, rows: np.ndarray):
        """weight(cosine) -> cosine * table(cosine) per shading point, for shading points of objects ``rows``."""
        mi = mitsuba()
        import drjit as dr

        mesh = self.mesh
        if np.all(mesh.tables[rows] == 1.0):
            return True          # all diffuse: the plain cosine
        tables = jit_array(mi.Float, mesh.tables.ravel())
        start = jit_array(mi.UInt32, (rows * TABLE_NODES).astype(np.uint32))

        def weight(cosine):
            x = dr.clip(cosine, 0.0, 1.0) * (TABLE_NODES - 1)
            i = dr.minimum(mi.UInt32(x), TABLE_NODES - 2)
            f = x - mi.Float(i)
            return cosine * ((1.0 - f) * dr.gather(mi.Float, tables, start + i)
                             + f * dr.gather(mi.Float, tables, start + i + 1))
        return weight
