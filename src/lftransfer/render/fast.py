"""The fast path of the renderer: irradiance cached at the vertices of a fine tessellation, glossy lobes per ray.

Light field transfer is low-pass (one spatial sample per lenslet), and the diffuse part of reflection depends on
irradiance only, so the expensive part of relighting, the sum over K lenslets with shadow rays, is done once per
*cache vertex* instead of once per ray: every synthetic object becomes a triangle mesh with edges of at most
``max_edge``, each triangle with its own three vertices (so sharp edges stay sharp), and the diffuse irradiance at
every vertex is computed with the same lights as the exact path (area, point or prefiltered model, shadow rays),
once per distinct (position, normal) pair (the triangles of one face share their corners: about a fifth of the
vertices, :class:`Tessellation`).
A light field or view render is then one ray cast per ray, a barycentric interpolation of the three vertex
irradiances and one evaluation of the material's diffuse lobe at the hit (its albedo texture at the hit's
texture coordinates).

Glossy and metal materials (Mitsuba's ``roughplastic`` / ``plastic`` and ``roughconductor`` / ``conductor``) are
split into their two lobes:

- the diffuse lobe of ``roughplastic`` is separable, f_d(wi, wo) cos_o = A(uv) t(cos_i) t(cos_o) cos_o (t the
  coating's transmittance), so the cache holds E_t = sum of L t(cos_o) / t(1) cos_o over the lights (the
  cosine weighted by the tabulated t(c) / t(1) of :func:`diffuse_lobe_table`) and a ray multiplies it by
  f_d(wi, n) = A(uv) t(cos_i) t(1), with no approximation beyond the interpolation;
- the view-dependent glossy lobe is evaluated per ray: point lights and emitters by their own next-event
  estimation restricted to the glossy lobe (one shadow ray, or the emitter samples, per ray); a light field of
  the area model by S * S directions drawn from the lobe (Mitsuba's own visible-normal sampling, stratified and
  multi-jittered, :func:`_lobe_direction`; S grows with the roughness, :func:`lobe_strata`; a view's rays, which
  are few and are what one sees, take ``view_lobe_samples``), each read where it meets the array plane
  (:meth:`LightFieldLight.incident`), an unbiased estimate of what the exact path sums over the lenslets'
  apertures; where the light field's K_active * M aperture points cost no more than those directions (few
  lit lenslets, rough lobes), the exact path's own lenslet sum (:meth:`LightFieldLight.reflect`) is added and
  the two are weighted by multiple importance sampling (balance heuristic). Neither casts rays: occlusion
  between a glossy object and the array comes from a second cache, the fraction of each lenslet's aperture
  (``VISIBILITY_POINTS`` points) that each cache vertex sees, interpolated like the irradiance and computed once
  per lens array while nothing moves (shadow rays only from points whose hemisphere holds another shape; the
  others see what lies in front of their tangent plane); on cache triangles across which that visibility
  changes (a shadow edge crosses them) the lobe's directions are cast against the scene instead. A view camera's
  rays all start at its centre, so a lobe of roughness at least ``PINHOLE_ROUGHNESS`` is not sampled at every
  view ray: its radiance towards the camera is computed once per distinct cache point with ``PINHOLE_SAMPLES``
  times the directions (the same estimators) and interpolated like the irradiance
  (:meth:`CachedRenderer._pinhole_glossy`); light field rays, which start all over the apertures, sample the lobe
  per ray. A smooth lobe (roughness 0) takes its one mirror direction.
  Under the point and prefiltered models the lenslets are points that no direction meets, and the glossy lobe is
  the exact path's lenslet sum with the cached visibility.

Synthetic objects that light each other (two or more reflecting objects, or a mesh) exchange light through an
interreflection gather (:class:`Interreflection`, ``bounces`` = the scene's ``max_depth`` - 1): every distinct
cache point casts ``GATHER_RAYS`` cosine-weighted directions once per arrangement of the objects, and each that
meets a cached surface reads the diffuse radiance leaving it from the cache, so a bounce is one sparse
matrix-vector product per colour channel; a glossy lobe at a point whose gather met a surface also casts its lobe
directions and reads the diffuse radiance of the surfaces they meet. The glossy light the objects reflect onto
each other is left out (reports say so).

One object laid on another (fig1b's photograph on its frame) buries the cache points under it
(:meth:`CachedRenderer._buried`): no camera sees them, but interpolated into the triangles they share with open
points they would draw a dark band along the covering object's edge (or, through the gather, a bright one). Their
irradiance and visibility are filled from the open points beside them, and the few hits in the gap under the
edge, where the light slips in at grazing angles, are shaded by the lights' own estimates with shadow rays.

When objects move (an animation frame, :meth:`CachedRenderer.update`), the moved objects' cache vertices are
moved in place (the refined local mesh is kept, the acceleration structure is rebuilt over the new vertex
positions; objects that move together, to ``TOGETHER`` at their points, keep their interreflection gather and
buried points: objects keyframed apart but meant as one drift by far less than a cache triangle) and every
light's irradiance is computed again (a moved object can shadow any other); while nothing moves, the irradiance
of each light is kept per light object, so a live loop that keeps its point light and swaps the captured light
field each frame relights only for the new light field.

What it keeps and what it drops against the exact path (:class:`~lftransfer.render.renderer.HalfSpaceRenderer`
with the scene's ``max_depth``): the light synthetic objects exchange is their diffuse light only, gathered over
``GATHER_RAYS`` directions per cache point; diffuse irradiance varies linearly across triangles of size
``max_edge`` (6 mm by default, four times finer than a lenslet), so diffuse shadow edges, and the light field's
shadows in glossy lobes, are blurred over one triangle; the glossy lobe is a Monte Carlo estimate with its own
noise (measured no larger than the exact path's at its default samples, for roughness >= :data:`MIN_ROUGHNESS`);
where the exact path (next-event estimation only) renders no light in a smooth (roughness 0) lobe, the fast path
renders the mirror image of the light field.
"""

from __future__ import annotations

import weakref
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.optics.geometry import plane_axes
from lftransfer.render.culling import TILE, RayTiles, bounding_spheres
from lftransfer.render.integrator import Light
from lftransfer.render.lights import jit_array, jit_rays, to_numpy
from lftransfer.render.renderer import HalfSpaceRenderer, SampleMeans, mean_depth
from lftransfer.render.shapes import bsdf_dict, emitter_dict, object_keys, shape_dict

DEFAULT_MAX_EDGE = 0.006  # m
DEFAULT_LOBE_SAMPLES = 16
DEFAULT_VIEW_LOBE_SAMPLES = 36   # ... per view ray: a view has few rays, and its pixels are what one sees
LOBE_ROUGHNESS = 0.15       # lobes up to this roughness take lobe_samples directions; rougher ones more
VISIBILITY_POINTS = 4       # aperture points per lenslet of the glossy lobes' visibility cache
TABLE_NODES = 64            # nodes of the diffuse lobe's cosine table (Mitsuba's roughplastic tabulates 64)
MATERIALS = ("diffuse", "glossy", "metal", "emitter")
PINHOLE_ROUGHNESS = 0.15    # glossy lobes at least this rough are read from the cache points in a view render
PINHOLE_SAMPLES = 4         # ... with this many times the lobe directions of a ray (the points are few)
GATHER_RAYS = 64            # cosine-weighted directions per cache point of the interreflection gather (8 x 8 strata)
CULL_BELOW = 0.25           # primary rays are culled by tile when fewer than this share of the tiles may hit
VARYING_VISIBILITY = 0.25   # a cache triangle whose corners see a lenslet this differently casts its lobes' rays
TOGETHER = 1e-4             # m: objects whose motions differ by less than this at their points move together
BURIED_DEPTH = 0.25         # of max_edge: a cache point with a surface this close in front of it is buried


#: Glossy and metal lobes at least this rough were measured against the exact path (tests/render/
#: measure_glossy.py): the fast path's error is no larger than the exact path's own at its default samples.
#: Below it, even 256 aperture points per lenslet leave the exact path unconverged, so neither is verified.
MIN_ROUGHNESS = 0.02


def supports(objects: Sequence) -> bool:
    """Whether the fast path renders these objects' materials (diffuse, glossy, metal, emitter)."""
    return all(getattr(o.material, "type", "diffuse") in MATERIALS for o in objects)


def verified(material) -> bool:
    """Whether the fast path's rendering of ``material`` was measured to be as accurate as the exact path's:
    diffuse and emitter materials, glossy and metal ones of roughness at least :data:`MIN_ROUGHNESS`."""
    return not _glossy(material) or material.roughness >= MIN_ROUGHNESS


def _glossy(material) -> bool:
    return material.type in ("glossy", "metal")


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


def diffuse_lobe_table(material) -> np.ndarray:
    """How the material's diffuse lobe weighs light by its cosine, relative to normal incidence.

    w(c) = f_d(n, wo(c)) / f_d(n, n) with cos(wo) = c, from Mitsuba's own BSDF evaluated with its diffuse
    component only (albedo 1, no texture): 1 for ``diffuse``, the coating's t(c) / t(1) for ``glossy``, 0 for
    ``metal`` and ``emitter`` (no diffuse lobe).

    Args:
        material: a scene material.

    Returns:
        (TABLE_NODES,) float32 at c = i / (TABLE_NODES - 1), read by linear interpolation.
    """
    mi = mitsuba()
    import drjit as dr

    if material.type == "diffuse":
        return np.ones(TABLE_NODES, np.float32)
    if material.type != "glossy":
        return np.zeros(TABLE_NODES, np.float32)
    white = material.model_copy(update={"albedo": [1.0, 1.0, 1.0], "texture": None})
    bsdf = mi.load_dict(bsdf_dict(white))
    c = np.maximum(np.linspace(0.0, 1.0, TABLE_NODES), 1e-4)
    si = dr.zeros(mi.SurfaceInteraction3f, TABLE_NODES)
    si.wi = mi.Vector3f(0.0, 0.0, 1.0)
    si.n = mi.Normal3f(0.0, 0.0, 1.0)
    si.sh_frame = mi.Frame3f(si.n)
    wo = mi.Vector3f(mi.Float(np.sqrt(1.0 - c**2)), 0.0, mi.Float(c))
    value = np.array(bsdf.eval(_context("diffuse"), si, wo), np.float64)[0] / c
    return (value / value[-1]).astype(np.float32)


def _context(lobe: str):
    """A BSDF context that enables only the diffuse lobe or only the glossy (and smooth) lobe."""
    mi = mitsuba()
    ctx = mi.BSDFContext()
    ctx.type_mask = mi.BSDFFlags.DiffuseReflection if lobe == "diffuse" \
        else mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.DeltaReflection
    return ctx


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


def exchanges_light(objects: Sequence) -> bool:
    """Whether the fast path's cached surfaces can light each other: two or more objects that reflect light, or a
    reflecting mesh (which may be concave); spheres, boxes, rectangles and cylinders alone cannot."""
    reflecting = [o for o in objects if o.material.type != "emitter"]
    return len(reflecting) > 1 or any(o.shape == "mesh" for o in reflecting)


def _moved_together(before: Sequence, after: Sequence, points: Sequence[np.ndarray]) -> bool:
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


@dataclass(frozen=True)
class _Burial:
    """The cache points buried under another surface (:meth:`CachedRenderer._buried`).

    Attributes:
        fill: ``scipy.sparse.csr_matrix`` (D, D) over the distinct points: a buried point's row averages the open
            points beside it, the others' rows are the identity's.
        covered: (F,) bool, the cache triangles with a buried corner.
        covered_jit: ``covered`` as mi.UInt32 (F,), for the renders.
    """

    fill: object
    covered: np.ndarray
    covered_jit: object


@dataclass(eq=False)
class _RaySet:
    """A constant ray set a renderer has cast (the memoised primary rays of a view or light field render).

    Attributes:
        origins, directions: weak references to its (N, 3) float32 arrays (identity is the key).
        renders: how many renders cast it.
        tiles: its cones for culling, once built (:meth:`CachedRenderer._ray_tiles`).
    """

    origins: weakref.ref
    directions: weakref.ref
    renders: int = 0
    tiles: RayTiles | None = None
    _centre: tuple = ()        # (centre,) once looked for

    def centre(self) -> np.ndarray | None:
        """(3,) the one origin every ray starts from (a view camera), or None; looked for once, when first asked
        (a pass over every origin, which only glossy lobes read from the cache points need)."""
        if not self._centre:
            origins = self.origins()
            self._centre = (np.array(origins[0], np.float64) if np.all(origins == origins[0]) else None,)
        return self._centre[0]


def group_means(idx: np.ndarray, colour: np.ndarray, t_hit: np.ndarray, groups: int, spp: int) -> SampleMeans:
    """:class:`SampleMeans` of ``groups`` groups of ``spp`` consecutive rays from the rays that hit only.

    The sums run over the groups with a hit (a view's objects cover a few per cent of its pixels), in float64 as
    a full-size ``np.bincount`` would sum them; the other groups are written once (black, coverage 0, depth inf).

    Args:
        idx: (H,) int64 ray indices of the hits, ascending.
        colour: (H, 3) float32 their radiance.
        t_hit: (H,) float32 their hit distances, metres.
        groups: G, the number of groups.
        spp: rays per group.
    """
    scale = 1.0 / spp
    radiance = np.zeros((groups, 3), np.float32)
    coverage = np.zeros(groups, np.float32)
    depth = np.full(groups, np.inf, np.float32)
    if len(idx):
        group = idx // spp
        first = np.empty(len(group), bool)          # the first hit of each group with a hit
        first[0] = True
        np.not_equal(group[1:], group[:-1], out=first[1:])
        dense = np.cumsum(first) - 1                # each hit's group among those with a hit
        hit = group[first]
        n = len(hit)
        flat = radiance.reshape(-1)
        for c in range(3):
            flat[hit * 3 + c] = np.bincount(dense, weights=colour[:, c], minlength=n) * scale
        hits = np.bincount(dense, minlength=n).astype(np.float32)
        coverage[hit] = hits * np.float32(scale)
        depth[hit] = mean_depth(np.bincount(dense, weights=t_hit, minlength=n), hits)
    return SampleMeans(radiance=radiance, coverage=coverage, depth=depth)


class CachedRenderer(HalfSpaceRenderer):
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

    Example:
        >>> r = CachedRenderer(scene.synthetic)                                   # doctest: +SKIP
        >>> lf = r.render_lightfield(array, lights, U=48, V=48, model="point")     # doctest: +SKIP
    """

    def __init__(self, objects: Sequence, *, max_edge: float = DEFAULT_MAX_EDGE,
                 lobe_samples: int = DEFAULT_LOBE_SAMPLES, view_lobe_samples: int = DEFAULT_VIEW_LOBE_SAMPLES,
                 glossy: bool = True, bounces: int = 0, gather_rays: int = GATHER_RAYS) -> None:
        if not supports(objects):
            raise ValueError(f"the fast path renders the materials {MATERIALS} only; use HalfSpaceRenderer")
        if lobe_samples < 1 or view_lobe_samples < 1:
            raise ValueError(f"lobe_samples and view_lobe_samples must be >= 1, got {lobe_samples} and "
                             f"{view_lobe_samples}")
        if bounces < 0 or gather_rays < 1:
            raise ValueError(f"bounces must be >= 0 and gather_rays >= 1, got {bounces} and {gather_rays}")
        self.max_edge = float(max_edge)
        self.lobe_samples = int(lobe_samples)
        self.view_lobe_samples = int(view_lobe_samples)
        self._samples = self.lobe_samples       # the lobe directions of the render under way
        self.glossy = bool(glossy)
        self.bounces = int(bounces)
        self.gather_rays = int(gather_rays)
        self.max_depth = 1 + self.bounces
        self._build(list(objects))

    def _build(self, objects: list) -> None:
        mi = mitsuba()
        import drjit as dr

        max_edge = self.max_edge
        self.objects = objects
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
            info.append((True, _glossy(obj.material), _glossy(obj.material) and obj.material.roughness == 0))
            base += len(v)
        self.scene = mi.load_dict({"type": "scene", **shapes}, parallel=False, optimize=False)
        self.vertices = np.concatenate(verts) if verts else np.zeros((0, 3), np.float32)   # (M, 3) cache points
        self.normals = np.concatenate(norms) if norms else np.zeros((0, 3), np.float32)    # (M, 3)
        self._rows = np.concatenate(rows) if rows else np.zeros(0, np.uint32)              # (M,) object index
        # (M,) index of each cache vertex among the distinct (position, normal) pairs, and (D,) one vertex of each:
        # irradiance and visibility are computed once per pair
        self._shared = np.concatenate(shared) if shared else np.zeros(0, np.int64)
        self._one_of = np.unique(self._shared, return_index=True)[1] if distinct else np.zeros(0, np.int64)
        self._pair = jit_array(mi.UInt32, self._shared.astype(np.uint32))
        self._tables = np.stack(tables).astype(np.float32)                                 # (objects, TABLE_NODES)
        self._reflects_diffuse = self._tables[:, -1] > 0                                   # (objects,)
        # Registry id of each loaded shape -> its first cache vertex and what its material does.
        ids = [int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(s))[0]) for s in self.scene.shapes()]
        order = {s.id(): i for i, s in enumerate(self.scene.shapes())}
        keys = list(shapes)
        table_base = np.zeros(max(ids) + 1, np.uint32)
        table_flags = np.zeros(max(ids) + 1, np.uint32)        # bit 0: cached, bit 1: glossy, bit 2: smooth,
        # bit 3: a glossy lobe rough enough to be read from the cache points towards a pinhole
        self._sids = np.zeros(len(keys), np.int64)              # registry id of each object's shape
        self._scene_index = np.zeros(len(keys), np.int64)       # its index in scene.shapes()
        self._pinhole_objects = np.array([_glossy(o.material) and o.material.roughness >= PINHOLE_ROUGHNESS
                                          for o in self.objects], bool)
        self._any_pinhole = self.glossy and bool(self._pinhole_objects.any())
        self._pinhole_memo = None
        for i, (key, b, (cached, glossy, smooth)) in enumerate(zip(keys, bases, info)):
            sid = ids[order[key]]
            self._sids[i] = sid
            table_base[sid] = b
            table_flags[sid] = int(cached) | (int(glossy) << 1) | (int(smooth) << 2) \
                | (int(bool(self._pinhole_objects[i])) << 3)
            self._scene_index[i] = order[key]
        self._flags_size = len(table_flags)
        self._base = jit_array(mi.UInt32, table_base)
        self._flags = jit_array(mi.UInt32, table_flags)
        self._any_glossy = self.glossy and any(glossy for _, glossy, _ in info)
        self._glossy_objects = np.array([_glossy(o.material) for o in self.objects], bool)
        self._visibility: dict = {}
        self._keys = keys
        self._bases = bases
        self._irradiance = None
        self._lit_by: tuple | None = None
        self._per_light: dict[int, tuple[object, list[np.ndarray]]] = {}
        self._gather: Interreflection | None = None
        self._burial: tuple = ()        # (the _Burial, or None where nothing is buried,) once found
        self._arranged = self._arrangement()

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
        mi = mitsuba()

        objects = list(objects)
        if not supports(objects):
            raise ValueError(f"the fast path renders the materials {MATERIALS} only; use HalfSpaceRenderer")
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
            cut = tessellation(objects[i], self.max_edge)
            v, n = cut.vertices, cut.normals
            end = self._bases[i + 1] if i + 1 < len(self._bases) else len(self.vertices)
            old = self._shared[self._bases[i]:end]
            if len(v) != end - self._bases[i] or not np.array_equal(cut.shared, old - (old.min() if len(old) else 0)):
                self._build(objects)
                return True
            params[f"{self._keys[i]}.vertex_positions"] = mi.Float(v.ravel())
            params[f"{self._keys[i]}.vertex_normals"] = mi.Float(n.ravel())
            self.vertices[self._bases[i]:end] = v
            self.normals[self._bases[i]:end] = n
        params.update()
        self.objects = objects
        if not _moved_together(self._arranged[0], objects, self._arranged[1]):
            self._gather = None
            self._burial = ()
            self._arranged = self._arrangement()
        self._visibility.clear()
        self._pinhole_memo = None
        self._per_light.clear()
        self._lit_by = None
        return True

    def _arrangement(self) -> tuple[list, list[np.ndarray]]:
        """(objects, per object its cache vertices (P, 3)): the arrangement the gather and the buried points were
        found for; each later pose is compared with it (:func:`_moved_together`), so that drifts add up."""
        ends = [*self._bases[1:], len(self.vertices)]
        return list(self.objects), [self.vertices[b:e].copy() for b, e in zip(self._bases, ends)]

    @property
    def exchanges(self) -> bool:
        """Whether this renderer's surfaces light each other (:func:`exchanges_light`)."""
        return exchanges_light(self.objects)

    def _interreflection(self) -> Interreflection:
        """The gather of :class:`Interreflection`, cast once per arrangement of the objects (kept while they move
        together)."""
        mi = mitsuba()
        import drjit as dr
        from scipy import sparse

        if self._gather is not None:
            return self._gather
        one = self._one_of
        m, count = len(self.vertices), len(one)
        rows_obj = self._rows[one]
        wanted = np.flatnonzero(self._reflects_diffuse[rows_obj] | self._glossy_objects[rows_obj])
        side = max(1, int(round(np.sqrt(self.gather_rays))))
        n = side * side
        rng = np.random.default_rng(0)
        j = np.arange(n)
        sx = (j % side + rng.random((len(wanted), n))) / side
        sy = (j // side + rng.random((len(wanted), n))) / side
        radius, phi = np.sqrt(sx), 2.0 * np.pi * sy
        cos_z = np.sqrt(np.maximum(1.0 - sx, 0.0))                       # (P, n) cosine to the normal
        normal = self.normals[one[wanted]].astype(np.float64)
        t, b, _ = plane_axes(normal)
        dirs = ((radius * np.cos(phi))[..., None] * t[:, None] + (radius * np.sin(phi))[..., None] * b[:, None]
                + cos_z[..., None] * normal[:, None]).reshape(-1, 3)
        origins = np.repeat(self.vertices[one[wanted]] + 1e-5 * normal, n, axis=0)
        rays = jit_rays(origins, dirs)
        pi = self.scene.ray_intersect_preliminary(rays)
        dr.eval(pi)
        hit = np.flatnonzero(np.isfinite(np.array(pi.t, np.float32)))
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
            cached = (dr.gather(mi.UInt32, self._flags, sid) & 1) != 0
            first = dr.gather(mi.UInt32, self._base, sid, cached) + pi.prim_index * 3
            f = si.bsdf().eval(_context("diffuse"), si, mi.Vector3f(0.0, 0.0, 1.0), cached)
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
                w[at] = np.interp(cos[at], nodes, self._tables[obj])
            weight = (np.pi / n) * w
            bary = np.stack([1.0 - b1 - b2, b1, b2], axis=1)[cached]       # (H', 3)
            rows = np.repeat(point, 3)
            cols = (first[cached][:, None] + np.arange(3)[None, :]).reshape(-1)
            for c in range(3):
                vals = ((weight * f[cached, c])[:, None] * bary).reshape(-1)
                matrices[c] = sparse.csr_matrix((vals.astype(np.float32), (rows, cols)), shape=(count, m))
        self._gather = Interreflection(matrices=tuple(matrices), sees=sees[self._shared], meets=meets[self._shared])
        self._sees = jit_array(mi.Float, self._gather.sees)
        return self._gather

    def _buried(self) -> _Burial | None:
        """The buried cache points and their fill (:class:`_Burial`, or None where nothing is buried), found once
        per arrangement of the objects (kept while they move together, like the gather).

        A cache point is buried when another surface lies less than ``BURIED_DEPTH * max_edge`` in front of it
        along its normal (the frame under a photograph laid on it): no camera sees it, but the triangles it shares
        with visible points would interpolate its darkness (or, in the gather, the light of the surface on top of
        it) into a band along the covering object's edge. The fill replaces a buried point's values by the mean of
        the unburied points it shares a triangle with (rows of the identity elsewhere; a point with no unburied
        neighbour takes its filled neighbours' mean, up to three rings, else keeps its own value).
        """
        mi = mitsuba()
        from scipy import sparse

        if self._burial:
            return self._burial[0]
        one, count = self._one_of, len(self._one_of)
        burial = None
        if count and exchanges_light(self.objects):
            n = self.normals[one].astype(np.float64)
            rays = jit_rays(self.vertices[one] + 1e-5 * n, n)
            pi = self.scene.ray_intersect_preliminary(rays)
            buried = np.array(pi.t, np.float64) < BURIED_DEPTH * self.max_edge
            if buried.any():
                corners = self._shared.reshape(-1, 3)
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
                burial = _Burial(fill.tocsr(), covered, jit_array(mi.UInt32, covered.astype(np.uint32)))
        self._burial = (burial,)
        return burial

    @contextmanager
    def _lobe_samples(self, count: int):
        """Draw ``count`` lobe directions per ray (instead of ``lobe_samples``) inside the block."""
        kept, self._samples = self._samples, int(count)
        try:
            yield
        finally:
            self._samples = kept

    def render_view(self, sensor, width: int, height: int, lights: Sequence[Light], *, spp: int = 4,
                    seed: int = 0):
        """:meth:`HalfSpaceRenderer.render_view`, its glossy lobes sampled with ``view_lobe_samples`` directions
        per ray."""
        with self._lobe_samples(self.view_lobe_samples):
            return super().render_view(sensor, width, height, lights, spp=spp, seed=seed)

    @property
    def cache_size(self) -> int:
        """Number of cache vertices M."""
        return len(self.vertices)

    def relight(self, lights: Sequence[Light], seed: int = 0) -> None:
        """Compute the diffuse irradiance at every cache vertex from ``lights`` (with shadow rays); a light
        object that lit the cache before, with nothing moved since, is not computed again."""
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
        if self.bounces and self.exchanges:
            gather = self._interreflection()
            bounce = total
            for _ in range(self.bounces):
                bounce = [gather.bounce(bounce[c], c, self._shared) for c in range(3)]
                total = [t + b for t, b in zip(total, bounce)]
        burial = self._buried()
        if burial is not None:
            total = [np.asarray(burial.fill @ t[self._one_of], np.float32)[self._shared] for t in total]
        self._irradiance = [jit_array(mi.Float, t) for t in total]
        self._lit_by = tuple(lights)

    def _irradiance_of(self, light: Light, seed: int) -> list[np.ndarray]:
        """(3,) arrays (M,) of one light's diffuse irradiance at the cache vertices: each direction weighted by
        its cosine times the vertex's material's :func:`diffuse_lobe_table` (zero for metals). It is computed once
        per distinct (position, normal) pair and read back at every cache vertex of the pair."""
        mi = mitsuba()
        import drjit as dr

        m = len(self.vertices)
        total = [np.zeros(m, np.float32) for _ in range(3)]
        one = self._one_of                      # (D,) a cache vertex of every distinct pair
        # Shade only the vertices with a diffuse lobe that this light can reach (a light field through the array
        # reaches those facing it on its side of the plane).
        wanted = self._reflects_diffuse[self._rows[one]] if m else np.zeros(0, bool)
        if hasattr(light, "may_light"):
            wanted &= light.may_light(self.vertices[one], self.normals[one])
        idx = one[wanted]
        if len(idx) == 0:
            return total
        v, n = self.vertices[idx], self.normals[idx]
        si = dr.zeros(mi.SurfaceInteraction3f, len(idx))
        si.p = mi.Point3f(*(jit_array(mi.Float, v[:, i]) for i in range(3)))
        si.n = mi.Normal3f(*(jit_array(mi.Float, n[:, i]) for i in range(3)))
        si.sh_frame = mi.Frame3f(si.n)
        si.wi = mi.Vector3f(0, 0, 1)
        weight = self._cosine_weight(self._rows[idx])
        e = np.array(light.illuminate(self.scene, si, mi.Bool(True), seed=seed, irradiance=weight), np.float32)
        per_pair = np.zeros((3, len(one)), np.float32)
        per_pair[:, wanted] = e
        return [per_pair[c][self._shared] for c in range(3)]

    def _cosine_weight(self, rows: np.ndarray):
        """weight(cosine) -> cosine * table(cosine) per shading point, for shading points of objects ``rows``."""
        mi = mitsuba()
        import drjit as dr

        if np.all(self._tables[rows] == 1.0):
            return True          # all diffuse: the plain cosine
        tables = jit_array(mi.Float, self._tables.ravel())
        start = jit_array(mi.UInt32, (rows * TABLE_NODES).astype(np.uint32))

        def weight(cosine):
            x = dr.clip(cosine, 0.0, 1.0) * (TABLE_NODES - 1)
            i = dr.minimum(mi.UInt32(x), TABLE_NODES - 2)
            f = x - mi.Float(i)
            return cosine * ((1.0 - f) * dr.gather(mi.Float, tables, start + i)
                             + f * dr.gather(mi.Float, tables, start + i + 1))
        return weight

    def _ray_set(self, origins: np.ndarray, directions: np.ndarray) -> _RaySet | None:
        """What this renderer knows of a constant ray set (the memoised primary rays, read-only, recognised by
        identity), with this render counted; None for other rays. A few sets are kept, by weak reference."""
        if origins.flags.writeable or directions.flags.writeable or not len(origins):
            return None
        sets = [r for r in self.__dict__.get("_ray_sets", []) if r.origins() is not None]
        found = next((r for r in sets if r.origins() is origins and r.directions() is directions), None)
        if found is None:
            found = _RaySet(weakref.ref(origins), weakref.ref(directions))
            sets = [*sets[-7:], found]
        self.__dict__["_ray_sets"] = sets
        found.renders += 1
        return found

    @staticmethod
    def _ray_tiles(ray_set: _RaySet | None, origins: np.ndarray, directions: np.ndarray) -> RayTiles | None:
        """The cones around tiles of a constant ray set, built at the set's second render (a live loop renders the
        same rays every frame; the bounce loop draws new ones per bounce, where building the tiles would cost more
        than they save) and kept with the set; None for other rays, small sets and at a set's first render (cast
        whole)."""
        if ray_set is None or ray_set.renders < 2 or len(origins) < 64 * TILE:
            return None
        if ray_set.tiles is None:
            ray_set.tiles = RayTiles.of(origins, directions)
        return ray_set.tiles

    def _hits(self, origins: np.ndarray, directions: np.ndarray, lights: Sequence[Light], seed: int
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One ray cast per ray and the cache lookup (and glossy lobe) at the hits only: (H,) int64 indices of the
        rays that hit, (H, 3) float32 their radiance and (H,) float32 their hit distances.

        Of a constant ray set (the primary rays) only the tiles whose cone meets an object's bounding sphere are
        cast (:mod:`lftransfer.render.culling`: the rays left out miss, so the result is the same)."""
        mi = mitsuba()
        import drjit as dr

        if self._lit_by is None or len(self._lit_by) != len(lights) or \
                any(a is not b for a, b in zip(self._lit_by, lights)):
            self.relight(lights, seed=seed)
        rays = self.jit_rays(origins, directions)
        cast = None                                    # indices of the rays cast (None: all of them)
        ray_set = self._ray_set(origins, directions)
        tiles = self._ray_tiles(ray_set, origins, directions)
        if tiles is not None:
            chosen = tiles.meeting(*bounding_spheres(self.scene))
            if chosen.mean() < CULL_BELOW:
                cast = tiles.rays(chosen)
                rays = dr.gather(mi.Ray3f, rays, jit_array(mi.UInt32, cast.astype(np.uint32)))
                dr.eval(rays)                # one kernel (the intersection would gather each field in its own)
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
        """:meth:`HalfSpaceRenderer.render_samples`, summed over the rays that hit only (a view's objects cover a
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
        (:meth:`_pinhole_glossy`), interpolated like the irradiance, instead of being sampled at every ray (not
        under a light field of the point or prefiltered model, whose point lenslets make sharp highlights)."""
        mi = mitsuba()
        import drjit as dr

        si = pi.compute_surface_interaction(rays, mi.RayFlags.All)
        sid = dr.reinterpret_array(mi.UInt32, pi.shape)
        flags = dr.gather(mi.UInt32, self._flags, sid)
        cached = (flags & 1) != 0

        def at(index):                       # the hits ``index``, computed again there (not gathered field by field)
            return dr.gather(mi.PreliminaryIntersection3f, pi, index).compute_surface_interaction(
                dr.gather(mi.Ray3f, rays, index), mi.RayFlags.All)

        first = dr.gather(mi.UInt32, self._base, sid, cached) + pi.prim_index * 3
        b1, b2 = pi.prim_uv.x, pi.prim_uv.y
        bary = (1.0 - b1 - b2, b1, b2)
        e = [self._interpolate(x, first, bary, cached) for x in self._irradiance]
        bsdf = si.bsdf()
        # the diffuse lobe towards the normal: albedo(uv) / pi for a diffuse material, A(uv) t(cos_i) t(1) for a
        # glossy one (module docs)
        f = bsdf.eval(_context("diffuse"), si, mi.Vector3f(0.0, 0.0, 1.0), cached)
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
                g = [self._interpolate(x, first, bary, at_points) for x in self._pinhole_glossy(pinhole, lights, seed)]
                out += dr.select(at_points, mi.Color3f(g[0], g[1], g[2]), 0.0)
                glossy &= ~at_points
            out += self._glossy(si, glossy, sid, flags, first, bary, lights, seed, at)
        return self._shade_under(at, first, cached, out, lights, seed)

    def _shade_under(self, at, first, active, out, lights: Sequence[Light], seed: int):
        """``out`` (mi.Color3f) with the hits that lie under another surface (less than ``BURIED_DEPTH * max_edge``
        along the normal: seen through the gap under a covering object's edge) shaded as the exact path shades
        them, by each light's own estimate with shadow rays, instead of from the cache, which holds there the
        values of the open surface beside them (:meth:`_buried`). Only hits on cache triangles with a buried
        corner are tested, compacted (they are few); ``at(index)`` is the surface interaction of the hits
        ``index``."""
        mi = mitsuba()
        import drjit as dr

        burial = self._buried()
        if burial is None:
            return out
        maybe = dr.compress(active & (dr.gather(mi.UInt32, burial.covered_jit, first // 3, active) != 0))
        if dr.width(maybe) == 0:
            return out
        hit = at(maybe)
        ray = hit.spawn_ray(mi.Vector3f(hit.n))
        ray.maxt = BURIED_DEPTH * self.max_edge
        under = self.scene.ray_test(ray)
        index = dr.gather(mi.UInt32, maybe, dr.compress(under))
        if dr.width(index) == 0:
            return out
        hit = at(index)
        value = mi.Color3f(0.0)
        for light in lights:                 # emitters too: the hits are on reflecting surfaces
            value += light.illuminate(self.scene, hit, mi.Bool(True), seed=seed)
        dr.eval(out, value)                  # one kernel each (scattered channel by channel, each would recompute)
        dr.scatter(out, value, index)
        return out

    @staticmethod
    def _interpolate(values, first, bary, active):
        """Barycentric interpolation of (M,) per-vertex ``values`` over the triangles starting at ``first``."""
        mi = mitsuba()
        import drjit as dr

        return (bary[0] * dr.gather(mi.Float, values, first, active)
                + bary[1] * dr.gather(mi.Float, values, first + 1, active)
                + bary[2] * dr.gather(mi.Float, values, first + 2, active))

    def _glossy(self, si, glossy, sid, flags, first, bary, lights: Sequence[Light], seed: int, at=None):
        """The glossy and metal lobes' light at the shading points ``si`` where ``glossy`` (mi.Color3f): point lights
        and emitters by their own sampling, a light field by :meth:`_lobe` (and the lenslet sum where it pays), the
        other cached surfaces by :meth:`_lobe_neighbours`; ``first`` and ``bary`` place each point in its cache
        triangle (for the visibility and gather tables); ``at(index)``: the shading points ``index`` (by default
        gathered from ``si``)."""
        mi = mitsuba()
        import drjit as dr

        if at is None:
            def at(index):
                return dr.gather(mi.SurfaceInteraction3f, si, index)
        out = mi.Color3f(0.0)
        smooth = (flags & 4) != 0
        ctx = _context("glossy")
        # the distinct cache point of each corner (the visibility tables hold one row per point)
        corners = [dr.gather(mi.UInt32, self._pair, first + c, glossy) for c in range(3)]
        b0, b1, b2 = bary
        for light in lights:
            if not hasattr(light, "reflect"):       # point lights, emitters: their own sampling
                out += light.illuminate(self.scene, si, glossy, seed=seed, ctx=ctx)
                continue
            table, varying = self._lenslet_visibility(light)
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
                out = self._lobe_cast(at, cast, by_lenslet, side, light, seed, out)
        if self.bounces and self.exchanges:       # the other objects' diffuse light in the lobe
            self._interreflection()
            sees = self._interpolate(self._sees, first, bary, glossy)
            out += self._lobe_neighbours(si, glossy & (sees > 0.0), seed)
        return out

    def _pinhole_glossy(self, origin: np.ndarray, lights: Sequence[Light], seed: int) -> list:
        """(3,) mi.Float (M,): the glossy lobes' radiance from every cache point of an object rough enough
        (:data:`PINHOLE_ROUGHNESS`) towards the point ``origin`` (a view camera's centre), zero elsewhere and at
        points facing away; computed by :meth:`_glossy` once per distinct cache point and kept while the lights,
        the seed and the objects stay."""
        mi = mitsuba()
        import drjit as dr

        key = (tuple(np.round(np.asarray(origin, np.float64), 9)), seed)
        kept = self._pinhole_memo
        if kept is not None and kept[0] == key and len(kept[1]) == len(lights) \
                and all(a is b for a, b in zip(kept[1], lights)):
            return kept[2]
        one = self._one_of
        m = len(self.vertices)
        rows = self._rows[one]
        x, n = self.vertices[one].astype(np.float64), self.normals[one].astype(np.float64)
        towards = np.asarray(origin, np.float64)[None, :] - x
        want = self._pinhole_objects[rows] & (np.einsum("dk,dk->d", towards, n) > 0) if m else np.zeros(0, bool)
        per_pair = np.zeros((len(one), 3), np.float32)
        if want.any():
            v = one[want]                                        # a cache vertex of each point
            w = towards[want] / np.linalg.norm(towards[want], axis=1, keepdims=True)
            si = dr.zeros(mi.SurfaceInteraction3f, len(v))
            si.p = mi.Point3f(*(jit_array(mi.Float, x[want][:, i]) for i in range(3)))
            si.n = mi.Normal3f(*(jit_array(mi.Float, n[want][:, i]) for i in range(3)))
            si.sh_frame = mi.Frame3f(si.n)
            si.wi = si.sh_frame.to_local(mi.Vector3f(*(jit_array(mi.Float, w[:, i]) for i in range(3))))
            si.shape = dr.gather(mi.ShapePtr, self.scene.shapes_dr(),
                                 jit_array(mi.UInt32, self._scene_index[rows[want]].astype(np.uint32)))
            sid = jit_array(mi.UInt32, self._sids[rows[want]].astype(np.uint32))
            flags = dr.gather(mi.UInt32, self._flags, sid)
            first = jit_array(mi.UInt32, (v - v % 3).astype(np.uint32))
            corner = v % 3
            bary = tuple(jit_array(mi.Float, (corner == c).astype(np.float32)) for c in range(3))
            with self._lobe_samples(self.lobe_samples * PINHOLE_SAMPLES):
                per_pair[want] = to_numpy(self._glossy(si, mi.Bool(True), sid, flags, first, bary, lights, seed))
        values = [jit_array(mi.Float, per_pair[self._shared, c]) for c in range(3)]
        self._pinhole_memo = (key, tuple(lights), values)
        return values

    def _lobe_neighbours(self, si, active, seed: int):
        """The diffuse light of the other cached surfaces that a glossy lobe reflects (mi.Color3f, (N,)):
        ``lobe_samples`` directions drawn from the lobe (stratified), each cast against the scene; a direction that
        meets a cached surface reads its diffuse radiance (irradiance cache times its diffuse lobe), one that meets
        nothing or the array is the light field's share (:meth:`_lobe`)."""
        mi = mitsuba()
        import drjit as dr

        n = dr.width(si.p)
        ctx = _context("glossy")
        diffuse = _context("diffuse")
        bsdf = si.bsdf()
        side = int(round(np.sqrt(self._base_samples())))
        count = side * side
        rng = mi.PCG32(n, dr.opaque(mi.UInt64, seed * 1000003 + 29), dr.arange(mi.UInt64, n))
        shift = _shifts(rng, mi.UInt32(side))
        irradiance = self._irradiance

        def cond(j, rng, acc):
            return active & (j < count)

        def body(j, rng, acc):
            bs, weight, ok = _lobe_direction(bsdf, ctx, si, rng, j, side, float(side), active, shift)
            ray = si.spawn_ray(si.to_world(bs.wo))
            pi = self.scene.ray_intersect_preliminary(ray, active=ok)
            sid = dr.reinterpret_array(mi.UInt32, pi.shape)
            met = ok & pi.is_valid()
            met &= (dr.gather(mi.UInt32, self._flags, sid, met) & 1) != 0
            hit = pi.compute_surface_interaction(ray, mi.RayFlags.All, met)
            first = dr.gather(mi.UInt32, self._base, sid, met) + pi.prim_index * 3
            bary = (1.0 - pi.prim_uv.x - pi.prim_uv.y, pi.prim_uv.x, pi.prim_uv.y)
            e = [self._interpolate(x, first, bary, met) for x in irradiance]
            f = hit.bsdf().eval(diffuse, hit, mi.Vector3f(0.0, 0.0, 1.0), met)
            acc += dr.select(met, weight * f * mi.Color3f(e[0], e[1], e[2]), 0.0)
            return j + 1, rng, acc

        _, _, acc = dr.while_loop((mi.UInt32(0), rng, mi.Color3f(0.0)), cond, body)
        return dr.select(active, acc / count, 0.0)

    def _base_samples(self) -> int:
        side0 = max(1, int(round(np.sqrt(self._samples))))
        return side0 * side0

    def _strategies(self, light):
        """Per shape registry id: the strata per axis of its glossy lobe's directions (mi.UInt32), and whether
        its lobe also sums the lenslets (mi.UInt32, 0 / 1): when the K_active * M aperture points of this light
        cost no more than the directions its roughness asks for (:func:`lobe_strata`), the lenslet sum and
        ``lobe_samples`` directions are combined by multiple importance sampling; otherwise the directions alone
        estimate the lobe. Also whether any shape sums the lenslets."""
        mi = mitsuba()
        cost = len(light.active_lenslets) * light.M
        strata = np.zeros(self._flags_size, np.uint32)
        summed = np.zeros(self._flags_size, np.uint32)
        side0 = int(round(np.sqrt(self._base_samples())))
        for sid, obj in zip(self._sids, self.objects):
            if not _glossy(obj.material):
                continue
            side = lobe_strata(obj.material.roughness, self._samples)
            if obj.material.roughness > 0 and cost <= side * side:
                strata[sid], summed[sid] = side0, 1
            else:
                strata[sid] = side
        return jit_array(mi.UInt32, strata), jit_array(mi.UInt32, summed), bool(summed.any())

    def _lobe_cast(self, at, cast, summed, strata, light, seed: int, out):
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
        ctx = _context("glossy")
        bsdf = si.bsdf()
        rng = mi.PCG32(n, dr.opaque(mi.UInt64, seed * 1000003 + 17), dr.arange(mi.UInt64, n))
        strata = dr.maximum(strata, 1)            # no integer division by zero in inactive lanes
        count = strata * strata
        side = mi.Float(strata)
        n_f = mi.Float(count)

        shift = _shifts(rng, strata)

        def visibility(k, w, ok):
            if seen is None:
                return dr.select(self.scene.ray_test(si.spawn_ray(w), ok), 0.0, 1.0)
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

    def _lenslet_visibility(self, light):
        """(table, varying): ``table`` mi.Float (D * K,), the fraction of each lenslet k's aperture
        (``VISIBILITY_POINTS`` stratified points) that distinct cache point d sees, at [d * K + k], computed for the
        points of glossy objects that the light may reach, once per lens array and side while nothing moves, buried
        points' rows filled (:meth:`_buried`); ``varying`` mi.UInt32 (F,), 1 on the cache triangles with a corner
        that cast shadow rays and corners' rows that differ by more than ``VARYING_VISIBILITY`` for some lenslet,
        or with a buried corner (a shadow edge or a covering object's edge crosses them: their lobes cast their
        directions), or None if there are none.

        A point whose hemisphere holds no other shape (a convex object alone, or none of the interreflection
        gather's directions met a shape) sees exactly the aperture points in front of its tangent plane; only the
        others cast shadow rays."""
        mi = mitsuba()
        import drjit as dr

        array = light.lightfield.array
        key = (array, light.side)
        if key in self._visibility:
            return self._visibility[key]
        m, K = len(self.vertices), array.K
        one = self._one_of                      # once per distinct (position, normal) pair
        wanted = self._glossy_objects[self._rows[one]] & light.may_light(self.vertices[one], self.normals[one]) \
            if m else np.zeros(0, bool)
        if len(self.objects) == 1 and self.objects[0].shape != "mesh":
            free = np.ones(len(one), bool)
        elif self.bounces and self.exchanges:
            free = self._interreflection().meets[one] == 0
        else:
            free = np.zeros(len(one), bool)
        seen = np.zeros((len(one), K), np.float32)
        offsets = array.sample_aperture(VISIBILITY_POINTS, seed=0)
        open_ = wanted & free
        if open_.any():
            x = self.vertices[one[open_]].astype(np.float64)
            n = self.normals[one[open_]].astype(np.float64)
            height = np.einsum("fk,fk->f", n, x)[:, None]
            front = np.zeros((len(x), K), np.float32)
            for offset in offsets:
                target = np.zeros((K, 3))
                target[:, :2] = array.centres + offset
                front += (n @ target.T > height).astype(np.float32)
            seen[open_] = front / len(offsets)
        shadowed = wanted & ~free
        idx = one[shadowed]
        if len(idx):
            x = np.repeat(self.vertices[idx], K, axis=0)                  # (len(idx) * K, 3), k fastest
            nrm = np.repeat(self.normals[idx], K, axis=0)
            si = dr.zeros(mi.SurfaceInteraction3f, len(x))
            si.p = mi.Point3f(*(jit_array(mi.Float, x[:, i]) for i in range(3)))
            si.n = mi.Normal3f(*(jit_array(mi.Float, nrm[:, i]) for i in range(3)))
            centres = np.tile(array.centres, (len(idx), 1))
            total = mi.Float(0.0)
            for offset in offsets:
                target = centres + offset
                p = mi.Point3f(jit_array(mi.Float, target[:, 0]), jit_array(mi.Float, target[:, 1]), 0.0)
                total += dr.select(self.scene.ray_test(si.spawn_ray_to(p)), 0.0, 1.0)
                dr.eval(total)
            seen[shadowed] = (np.array(total, np.float32) / len(offsets)).reshape(len(idx), K)
        burial = self._buried()
        corners = self._shared.reshape(-1, 3)                            # (F, 3) distinct point of each corner
        varying = np.zeros(len(corners), bool)
        check = shadowed[corners].any(axis=1)                  # triangles whose shadows came from shadow rays
        if check.any():
            rows = seen[corners[check]]                                  # (F', 3, K)
            varying[check] = (rows.max(axis=1) - rows.min(axis=1)).max(axis=1) > VARYING_VISIBILITY
        if burial is not None:
            varying |= burial.covered
            seen = np.asarray(burial.fill @ seen, np.float32)
        varying = jit_array(mi.UInt32, varying.astype(np.uint32)) if varying.any() else None
        self._visibility[key] = (jit_array(mi.Float, seen), varying)
        return self._visibility[key]
