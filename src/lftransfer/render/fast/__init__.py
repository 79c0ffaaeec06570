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
  multi-jittered, :func:`~lftransfer.render.fast.glossy._lobe_direction`; S grows with the roughness,
  :func:`lobe_strata`; a view's rays, which are few and are what one sees, take ``view_lobe_samples``), each read
  where it meets the array plane
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
  (:meth:`~lftransfer.render.fast.glossy.GlossyLobes.pinhole`); light field rays, which start all over the
  apertures, sample the lobe per ray. A smooth lobe (roughness 0) takes its one mirror direction.
  Under the point and prefiltered models the lenslets are points that no direction meets, and the glossy lobe is
  the exact path's lenslet sum with the cached visibility.

Synthetic objects that light each other (two or more reflecting objects, or a mesh) exchange light through an
interreflection gather (:class:`Interreflection`, ``max_depth`` - 1 rounds, as the exact path counts depth): every
distinct cache point casts ``GATHER_RAYS`` cosine-weighted directions once per arrangement of the objects, and each
that meets a cached surface reads the diffuse radiance leaving it from the cache, so a round is one sparse
matrix-vector product per colour channel; a glossy lobe at a point whose gather met a surface also casts its lobe
directions and reads the diffuse radiance of the surfaces they meet. The glossy light the objects reflect onto each
other is left out (reports say so).

One object laid on another (fig1b's photograph on its frame) buries the cache points under it
(:meth:`~lftransfer.render.fast.interreflection.Arrangement.burial`): no camera sees them, but interpolated into the
triangles they share with open points they would draw a dark band along the covering object's edge (or, through
the gather, a bright one). Their irradiance and visibility are filled from the open points beside them, and the few
hits in the gap under the edge, where the light slips in at grazing angles, are shaded by the lights' own estimates
with shadow rays.

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

The package, one job a module: :mod:`~lftransfer.render.fast.materials` (which materials, their diffuse lobe's
cosine table), :mod:`~lftransfer.render.fast.tessellation` (the synthetic shapes as a fine triangle soup),
:mod:`~lftransfer.render.fast.mesh` (the cache's geometry in one Mitsuba scene), :mod:`~lftransfer.render.fast.
irradiance` (the irradiance cache at the vertices), :mod:`~lftransfer.render.fast.interreflection` (the gather
between synthetic objects, kept per arrangement), :mod:`~lftransfer.render.fast.burial` (buried cache points),
:mod:`~lftransfer.render.fast.glossy` (the glossy lobes), :mod:`~lftransfer.render.fast.visibility` (their
lenslet visibility cache), :mod:`~lftransfer.render.fast.rays` (primary ray sets, culling, per-pixel means) and
:mod:`~lftransfer.render.fast.renderer` (:class:`CachedRenderer`, which composes them).
"""

from __future__ import annotations

from lftransfer.render.fast.burial import BURIED_DEPTH
from lftransfer.render.fast.glossy import (DEFAULT_LOBE_SAMPLES, DEFAULT_VIEW_LOBE_SAMPLES, LOBE_ROUGHNESS,
                                           PINHOLE_ROUGHNESS, PINHOLE_SAMPLES, lobe_strata)
from lftransfer.render.fast.interreflection import GATHER_RAYS, TOGETHER, Interreflection, exchanges_light
from lftransfer.render.fast.materials import (MATERIALS, MIN_ROUGHNESS, TABLE_NODES, diffuse_lobe_table, supports,
                                              verified)
from lftransfer.render.fast.rays import CULL_BELOW, group_means
from lftransfer.render.fast.renderer import CachedRenderer
from lftransfer.render.fast.tessellation import DEFAULT_MAX_EDGE, Tessellation, tessellate, tessellation, texcoords
from lftransfer.render.fast.visibility import VARYING_VISIBILITY, VISIBILITY_POINTS

__all__ = [
    "BURIED_DEPTH", "CULL_BELOW", "DEFAULT_LOBE_SAMPLES", "DEFAULT_MAX_EDGE", "DEFAULT_VIEW_LOBE_SAMPLES",
    "GATHER_RAYS", "LOBE_ROUGHNESS", "MATERIALS", "MIN_ROUGHNESS", "PINHOLE_ROUGHNESS", "PINHOLE_SAMPLES",
    "TABLE_NODES", "TOGETHER", "VARYING_VISIBILITY", "VISIBILITY_POINTS",
    "CachedRenderer", "Interreflection", "Tessellation",
    "diffuse_lobe_table", "exchanges_light", "group_means", "lobe_strata", "supports", "tessellate", "tessellation",
    "texcoords", "verified",
]
