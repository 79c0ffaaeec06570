"""Interreflection between the synthetic objects: the diffuse light the cached surfaces send each other as a linear
map of the cache's irradiance (:class:`Interreflection`, cast by :func:`cast_gather`), and what the cached surfaces
are to each other in one arrangement of the objects, kept while they move together (:class:`Arrangement`: the
gather and the buried points)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.optics.geometry import plane_axes
from lftransfer.render.fast.burial import Burial, find_burial
from lftransfer.render.fast.materials import TABLE_NODES, bsdf_context
from lftransfer.render.fast.mesh import CacheMesh
from lftransfer.render.lights import jit_array, jit_rays, to_numpy

GATHER_RAYS = 64            # cosine-weighted directions per cache point of the interreflection gather (8 x 8 strata)
TOGETHER = 1e-4             # m: objects whose motions differ by less than this at their points move together


def exchanges_light(objects: Sequence) -> bool:
    """Whether the fast path's cached surfaces can light each other: two or more objects that reflect light, or a
    reflecting mesh (which may be concave); spheres, boxes, rectangles and cylinders alone cannot."""
    reflecting = [o for o in objects if o.material.type != "emitter"]
    return len(reflecting) > 1 or any(o.shape == "mesh" for o in reflecting)


def moved_together(before: Sequence, after: Sequence, points: Sequence[np.ndarray]) -> bool:
    """Whether every reflecting object moved by one common rigid motion, up to ``TOGETHER`` (then the light they
    exchange is unchanged: the interreflection gather is kept).

    Args:
        before, after: the objects' two poses.
        points: per object, (P, 3) points of it in the pose ``before`` (its cache vertices; emitters: any).

    Objects keyframed separately but meant to move as one (fig1b's photograph on its frame) drift apart by
    far less than a cache triangle while the motion is interpolated: each object's points are moved by every
    object's motion and compared.
    """
    pairs = [(a.to_world(), b.to_world(), x) for a, b, x in zip(before, after, points)
             if a.material.type != "emitter" and len(x)]
    if not pairs:
        return True
    deltas = [b @ np.linalg.inv(a) for a, b, _ in pairs]
    for _, _, x in pairs:
        h = np.c_[x, np.ones(len(x))].T                           # (4, P) homogeneous
        if any(np.abs((d - deltas[0]) @ h).max() > TOGETHER for d in deltas[1:]):
            return False
    return True


@dataclass(frozen=True)
class Interreflection:
    """The diffuse light the cached surfaces send each other, as a linear map of the cache's irradiance.

    Every distinct cache point d gathers ``rays`` cosine-weighted directions (stratified); a direction that meets
    a cached surface at barycentrics b on triangle f reads the diffuse radiance leaving it, f_d(hit) * sum_c b_c
    E[3f + c] (the cache's own lookup), so the irradiance d receives is (pi / rays) * sum over its hits of
    w_d(cos) f_d b_c E[3f + c], w_d the receiver's :func:`diffuse_lobe_table`. One application is one bounce.

    Attributes:
        matrices: per channel a ``scipy.sparse.csr_matrix`` (D, M): distinct points x cache vertices.
        sees: (M,) float32 share of each cache vertex's directions that meet a cached surface.
        meets: (M,) float32 share that meet any shape (an emitter's too).
    """

    matrices: tuple
    sees: np.ndarray
    meets: np.ndarray

    def bounce(self, irradiance: np.ndarray, channel: int, shared: np.ndarray) -> np.ndarray:
        """(M,) float32: the irradiance one bounce adds, from the cache's (M,) ``irradiance`` of ``channel``."""
        return np.asarray(self.matrices[channel] @ irradiance, np.float32)[shared]


def cast_gather(mesh: CacheMesh, gather_rays: int, windows=None) -> Interreflection:
    """The gather of :class:`Interreflection` over the cache ``mesh``: ``gather_rays`` cosine-weighted directions
    per distinct cache point (stratified), cast once per arrangement of the objects (:class:`Arrangement`); a
    direction that crosses one of several interfaces' arrays (``windows``, :mod:`lftransfer.render.windows`) before
    its hit meets nothing."""
    mi = mitsuba()
    import drjit as dr
    from scipy import sparse

    one = mesh.one_of
    m, count = len(mesh.vertices), len(one)
    rows_obj = mesh.rows[one]
    wanted = np.flatnonzero(mesh.reflects_diffuse[rows_obj] | mesh.glossy_objects[rows_obj])
    side = max(1, int(round(np.sqrt(gather_rays))))
    n = side * side
    rng = np.random.default_rng(0)
    j = np.arange(n)
    sx = (j % side + rng.random((len(wanted), n))) / side
    sy = (j // side + rng.random((len(wanted), n))) / side
    radius, phi = np.sqrt(sx), 2.0 * np.pi * sy
    cos_z = np.sqrt(np.maximum(1.0 - sx, 0.0))                       # (P, n) cosine to the normal
    normal = mesh.normals[one[wanted]].astype(np.float64)
    t, b, _ = plane_axes(normal)
    dirs = ((radius * np.cos(phi))[..., None] * t[:, None] + (radius * np.sin(phi))[..., None] * b[:, None]
            + cos_z[..., None] * normal[:, None]).reshape(-1, 3)
    origins = np.repeat(mesh.vertices[one[wanted]] + 1e-5 * normal, n, axis=0)
    rays = jit_rays(origins, dirs)
    pi = mesh.scene.ray_intersect_preliminary(rays)
    dr.eval(pi)
    reach = np.array(pi.t, np.float32)
    if windows is not None:
        reach[windows.crossed(origins, dirs, reach)] = np.inf
    hit = np.flatnonzero(np.isfinite(reach))
    matrices = [sparse.csr_matrix((count, m), dtype=np.float32) for _ in range(3)]
    sees = np.zeros(count, np.float32)
    meets = np.zeros(count, np.float32)
    np.add.at(meets, wanted[hit // n], 1.0 / n)
    if len(hit):
        index = jit_array(mi.UInt32, hit.astype(np.uint32))
        pi = dr.gather(mi.PreliminaryIntersection3f, pi, index)
        rays = dr.gather(mi.Ray3f, rays, index)
        si = pi.compute_surface_interaction(rays, mi.RayFlags.All)
        sid = dr.reinterpret_array(mi.UInt32, pi.shape)
        cached = (dr.gather(mi.UInt32, mesh.flags, sid) & 1) != 0
        first = dr.gather(mi.UInt32, mesh.base, sid, cached) + pi.prim_index * 3
        f = si.bsdf().eval(bsdf_context("diffuse"), si, mi.Vector3f(0.0, 0.0, 1.0), cached)
        cached = np.array(cached, bool)
        f = to_numpy(f).astype(np.float64)                             # (H, 3) diffuse radiance per irradiance
        first = np.array(first, np.int64)
        b1, b2 = np.array(pi.prim_uv.x, np.float64), np.array(pi.prim_uv.y, np.float64)
        ray = hit[cached]
        point = wanted[ray // n]                                        # receiving distinct point
        np.add.at(sees, point, 1.0 / n)
        cos = cos_z.reshape(-1)[ray]
        receiver = rows_obj[point]                                      # the receiving object's lobe table
        nodes = np.linspace(0.0, 1.0, TABLE_NODES)
        w = np.empty(len(cos))
        for obj in np.unique(receiver):
            at = receiver == obj
            w[at] = np.interp(cos[at], nodes, mesh.tables[obj])
        weight = (np.pi / n) * w
        bary = np.stack([1.0 - b1 - b2, b1, b2], axis=1)[cached]       # (H', 3)
        rows = np.repeat(point, 3)
        cols = (first[cached][:, None] + np.arange(3)[None, :]).reshape(-1)
        for c in range(3):
            vals = ((weight * f[cached, c])[:, None] * bary).reshape(-1)
            matrices[c] = sparse.csr_matrix((vals.astype(np.float32), (rows, cols)), shape=(count, m))
    return Interreflection(matrices=tuple(matrices), sees=sees[mesh.shared], meets=meets[mesh.shared])


class Arrangement:
    """What the cached surfaces are to each other in one arrangement of the objects: the interreflection gather
    (:func:`cast_gather`) and the buried points (:func:`~lftransfer.render.fast.burial.find_burial`), each found
    when first asked and kept while the objects move together (:meth:`follow`).

    Args:
        mesh: the cache's geometry (moved in place when the objects move).
        gather_rays: cosine-weighted directions per cache point of the gather.

    Attributes:
        sees: the gather's ``sees`` as mi.Float (M,), once the gather is cast.
    """

    def __init__(self, mesh: CacheMesh, gather_rays: int, windows=None) -> None:
        self.mesh = mesh
        self.gather_rays = int(gather_rays)
        self.windows = windows
        self.sees = None
        self._gather: Interreflection | None = None
        self._burial: tuple = ()        # (the Burial, or None where nothing is buried,) once found
        self._arranged = mesh.arrangement()

    def gather(self) -> Interreflection:
        """The gather of :class:`Interreflection`, cast once per arrangement of the objects (kept while they move
        together)."""
        mi = mitsuba()

        if self._gather is not None:
            return self._gather
        self._gather = cast_gather(self.mesh, self.gather_rays, self.windows)
        self.sees = jit_array(mi.Float, self._gather.sees)
        return self._gather

    def burial(self) -> Burial | None:
        """The buried cache points and their fill (:class:`~lftransfer.render.fast.burial.Burial`, or None where
        nothing is buried: also where the objects cannot light each other), found once per arrangement of the
        objects (kept while they move together, like the gather)."""
        if self._burial:
            return self._burial[0]
        burial = find_burial(self.mesh) if exchanges_light(self.mesh.objects) else None
        self._burial = (burial,)
        return burial

    def follow(self) -> None:
        """After the mesh moved: unless every reflecting object moved by one common rigid motion since the gather
        and the buried points were found (:func:`moved_together`, measured from that arrangement, so that drifts
        add up), forget them."""
        if not moved_together(self._arranged[0], self.mesh.objects, self._arranged[1]):
            self._gather = None
            self._burial = ()
            self._arranged = self.mesh.arrangement()
