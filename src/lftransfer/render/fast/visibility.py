"""The glossy lobes' occlusion between the cache points and the lenslets: the fraction of each lenslet's aperture
that each distinct cache point sees, computed once per lens array and side while nothing moves, and the cache
triangles across which it changes (:class:`LensletVisibility`)."""

from __future__ import annotations

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.render.fast.interreflection import Arrangement, exchanges_light
from lftransfer.render.fast.mesh import CacheMesh
from lftransfer.render.lights import jit_array

VISIBILITY_POINTS = 4       # aperture points per lenslet of the glossy lobes' visibility cache
VARYING_VISIBILITY = 0.25   # a cache triangle whose corners see a lenslet this differently casts its lobes' rays


class LensletVisibility:
    """The lenslet visibility of the cache's glossy points, per lens array and side (:meth:`of`).

    Args:
        mesh: the cache's geometry.
        arrangement: its interreflection gather (which points' hemispheres hold another shape) and buried points.
        gathers: rounds of the interreflection gather (with none, the gather is not cast and every point casts
            shadow rays).

    Attributes:
        tables: {(lens array, side): (table, varying)}, what :meth:`of` found while nothing moved.
    """

    def __init__(self, mesh: CacheMesh, arrangement: Arrangement, gathers: int) -> None:
        self.mesh = mesh
        self.arrangement = arrangement
        self.gathers = int(gathers)
        self.tables: dict = {}

    def forget(self) -> None:
        """The objects moved: every table is stale."""
        self.tables.clear()

    def of(self, light) -> tuple:
        """(table, varying): ``table`` mi.Float (D * K,), the fraction of each lenslet k's aperture
        (``VISIBILITY_POINTS`` stratified points) that distinct cache point d sees, at [d * K + k], computed for the
        points of glossy objects that the light may reach, once per lens array and side while nothing moves, buried
        points' rows filled (:meth:`Arrangement.burial`); ``varying`` mi.UInt32 (F,), 1 on the cache triangles with
        a corner that cast shadow rays and corners' rows that differ by more than ``VARYING_VISIBILITY`` for some
        lenslet, or with a buried corner (a shadow edge or a covering object's edge crosses them: their lobes cast
        their directions), or None if there are none.

        A point whose hemisphere holds no other shape (a convex object alone, or none of the interreflection
        gather's directions met a shape) sees exactly the aperture points in front of its tangent plane; only the
        others cast shadow rays."""
        mi = mitsuba()
        import drjit as dr

        array = light.lightfield.array
        key = (array, light.side, None if light.pose is None else light.pose.tobytes())
        if key in self.tables:
            return self.tables[key]
        mesh = self.mesh
        m, K = len(mesh.vertices), array.K
        one = mesh.one_of                      # once per distinct (position, normal) pair
        wanted = mesh.glossy_objects[mesh.rows[one]] & light.may_light(mesh.vertices[one], mesh.normals[one]) \
            if m else np.zeros(0, bool)
        if len(mesh.objects) == 1 and mesh.objects[0].shape != "mesh":
            free = np.ones(len(one), bool)
        elif self.gathers and exchanges_light(mesh.objects):
            free = self.arrangement.gather().meets[one] == 0
        else:
            free = np.zeros(len(one), bool)
        seen = np.zeros((len(one), K), np.float32)
        offsets = array.sample_aperture(VISIBILITY_POINTS, seed=0)
        open_ = wanted & free
        if open_.any():
            x = mesh.vertices[one[open_]].astype(np.float64)
            n = mesh.normals[one[open_]].astype(np.float64)
            height = np.einsum("fk,fk->f", n, x)[:, None]
            front = np.zeros((len(x), K), np.float32)
            for offset in offsets:
                target = np.zeros((K, 3))
                target[:, :2] = array.centres + offset
                front += (n @ light.to_lit_frame(target).T > height).astype(np.float32)
            seen[open_] = front / len(offsets)
        shadowed = wanted & ~free
        idx = one[shadowed]
        if len(idx):
            x = np.repeat(mesh.vertices[idx], K, axis=0)                  # (len(idx) * K, 3), k fastest
            nrm = np.repeat(mesh.normals[idx], K, axis=0)
            si = dr.zeros(mi.SurfaceInteraction3f, len(x))
            si.p = mi.Point3f(*(jit_array(mi.Float, x[:, i]) for i in range(3)))
            si.n = mi.Normal3f(*(jit_array(mi.Float, nrm[:, i]) for i in range(3)))
            centres = np.tile(array.centres, (len(idx), 1))
            total = mi.Float(0.0)
            for offset in offsets:
                target = light.to_lit_frame(np.column_stack([centres + offset, np.zeros(len(centres))]))
                p = mi.Point3f(*(jit_array(mi.Float, target[:, i]) for i in range(3)))
                total += dr.select(mesh.scene.ray_test(si.spawn_ray_to(p)), 0.0, 1.0)
                dr.eval(total)
            seen[shadowed] = (np.array(total, np.float32) / len(offsets)).reshape(len(idx), K)
        burial = self.arrangement.burial()
        corners = mesh.shared.reshape(-1, 3)                            # (F, 3) distinct point of each corner
        varying = np.zeros(len(corners), bool)
        check = shadowed[corners].any(axis=1)                  # triangles whose shadows came from shadow rays
        if check.any():
            rows = seen[corners[check]]                                  # (F', 3, K)
            varying[check] = (rows.max(axis=1) - rows.min(axis=1)).max(axis=1) > VARYING_VISIBILITY
        if burial is not None:
            varying |= burial.covered
            seen = np.asarray(burial.fill @ seen, np.float32)
        varying = jit_array(mi.UInt32, varying.astype(np.uint32)) if varying.any() else None
        self.tables[key] = (jit_array(mi.Float, seen), varying)
        return self.tables[key]
