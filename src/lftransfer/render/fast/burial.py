"""Cache points buried under another surface (fig1b's photograph laid on its frame): found once per arrangement
(:func:`find_burial`), their values filled from the open points beside them, and the hits in the gap under a
covering object's edge shaded by the lights' own estimates (:func:`shade_under`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.render.integrator import Light
from lftransfer.render.lights import jit_array, jit_rays

BURIED_DEPTH = 0.25         # of max_edge: a cache point with a surface this close in front of it is buried


@dataclass(frozen=True)
class Burial:
    """The cache points buried under another surface (:func:`find_burial`).

    Attributes:
        fill: ``scipy.sparse.csr_matrix`` (D, D) over the distinct points: a buried point's row averages the open
            points beside it, the others' rows are the identity's.
        covered: (F,) bool, the cache triangles with a buried corner.
        covered_jit: ``covered`` as mi.UInt32 (F,), for the renders.
    """

    fill: object
    covered: np.ndarray
    covered_jit: object


def find_burial(mesh) -> Burial | None:
    """The buried cache points of the cache ``mesh`` (a :class:`~lftransfer.render.fast.mesh.CacheMesh`) and their
    fill (:class:`Burial`, or None where nothing is buried), found once per arrangement of the objects
    (:class:`~lftransfer.render.fast.interreflection.Arrangement`: kept while they move together, like the gather).

    A cache point is buried when another surface lies less than ``BURIED_DEPTH * max_edge`` in front of it
    along its normal (the frame under a photograph laid on it): no camera sees it, but the triangles it shares
    with visible points would interpolate its darkness (or, in the gather, the light of the surface on top of
    it) into a band along the covering object's edge. The fill replaces a buried point's values by the mean of
    the unburied points it shares a triangle with (rows of the identity elsewhere; a point with no unburied
    neighbour takes its filled neighbours' mean, up to three rings, else keeps its own value).
    """
    mi = mitsuba()
    from scipy import sparse

    one, count = mesh.one_of, len(mesh.one_of)
    burial = None
    if count:
        n = mesh.normals[one].astype(np.float64)
        rays = jit_rays(mesh.vertices[one] + 1e-5 * n, n)
        pi = mesh.scene.ray_intersect_preliminary(rays)
        buried = np.array(pi.t, np.float64) < BURIED_DEPTH * mesh.max_edge
        if buried.any():
            corners = mesh.shared.reshape(-1, 3)
            edges = np.concatenate([corners[:, [a, b]] for a, b in ((0, 1), (1, 2), (2, 0))])
            edges = np.concatenate([edges, edges[:, ::-1]])
            adjacency = sparse.csr_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(count, count))
            adjacency.data[:] = 1.0                       # duplicate edges count once
            fill = sparse.identity(count, format="csr")
            known = ~buried
            for _ in range(3):                             # ring by ring away from the unburied points
                cols = np.flatnonzero(known)
                reach = np.asarray(adjacency[:, cols].sum(axis=1)).ravel()
                rows = np.flatnonzero(~known & (reach > 0))
                if not len(rows):
                    break
                step = adjacency[rows][:, cols].tocoo()
                keep = np.setdiff1d(np.arange(count), rows)
                update = sparse.csr_matrix(
                    (np.concatenate([np.ones(len(keep)), step.data / reach[rows][step.row]]),
                     (np.concatenate([keep, rows[step.row]]), np.concatenate([keep, cols[step.col]]))),
                    shape=(count, count))
                fill = update @ fill
                known[rows] = True
            covered = buried[corners].any(axis=1)
            burial = Burial(fill.tocsr(), covered, jit_array(mi.UInt32, covered.astype(np.uint32)))
    return burial


def shade_under(mesh, burial: Burial | None, at, first, active, out, lights: Sequence[Light], seed: int):
    """``out`` (mi.Color3f) with the hits that lie under another surface (less than ``BURIED_DEPTH * max_edge``
    along the normal: seen through the gap under a covering object's edge) shaded as the exact path shades
    them, by each light's own estimate with shadow rays, instead of from the cache, which holds there the
    values of the open surface beside them (``burial``, what :func:`find_burial` found, or None). Only hits on
    cache triangles with a buried corner are tested, compacted (they are few); ``at(index)`` is the surface
    interaction of the hits ``index``; ``mesh`` the cache's geometry."""
    mi = mitsuba()
    import drjit as dr

    if burial is None:
        return out
    maybe = dr.compress(active & (dr.gather(mi.UInt32, burial.covered_jit, first // 3, active) != 0))
    if dr.width(maybe) == 0:
        return out
    hit = at(maybe)
    ray = hit.spawn_ray(mi.Vector3f(hit.n))
    ray.maxt = BURIED_DEPTH * mesh.max_edge
    under = mesh.scene.ray_test(ray)
    index = dr.gather(mi.UInt32, maybe, dr.compress(under))
    if dr.width(index) == 0:
        return out
    hit = at(index)
    value = mi.Color3f(0.0)
    for light in lights:                 # emitters too: the hits are on reflecting surfaces
        value += light.illuminate(mesh.scene, hit, mi.Bool(True), seed=seed)
    dr.eval(out, value)                  # one kernel each (scattered channel by channel, each would recompute)
    dr.scatter(out, value, index)
    return out
