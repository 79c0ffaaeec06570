"""Light sources of the renderer: the point light, emitting objects, an environment map and a light field seen through
the lens array.

Each light adds its reflected radiance at a batch of surface points in one call (next-event estimation with
shadow rays). The light field light is the paper's interface seen from one half-space: every lenslet k is an
emitter whose radiance depends on direction only (docs/architecture.md, "Radiometry of a lenslet"). Three lighting
models:

- ``"point"``: the paper's approximation. Lenslet k collapses to a projective point light at its centre c_k
  with intensity I_k(w) = L_k(w) A |w_z|; a point x receives I_k cos(theta_x) / r^2.
- ``"area"``: the physical model. The aperture (lattice cell) is sampled with M stratified points p and
  x receives sum_p L_k(w(p -> x)) cos(theta_p) cos(theta_x) / |x - p|^2 * A / M.
- ``"prefiltered"``: point-light cost, one lookup per lenslet in the angular texture blurred by the angle
  that the aperture subtends from x (a box filter of half-width sqrt(A) / (2 |x_z|) in (u, v)), with
  one shadow ray to the centre.

How the light field is read between lenslet centres (the area model's ``reconstruction``):

- ``"box"``: every point of lenslet k's aperture sends L_k(w), one spatial sample per lenslet (what the
  projector's lenslets physically do).
- ``"linear"``: the aperture point p sends sum_j b_j(p) L_j(w), the barycentric blend of the three lenslets of
  the lattice triangle around p at the same direction (:meth:`LensArray.interpolation`): continuous in
  position, the same flux per lenslet. A captured sample L_k(w) is the average of the true light field over
  aperture k, so this is the piecewise-linear reading of those averages.

What arrives from beyond the lenslets' window (|u| or |v| > a, about 26.6 degrees off the normal: light no
lenslet's pixels record), the light field light's ``window``:

- ``"cut"``: nothing, the light field as the hardware records it.
- ``"edge"``: the window's edge, out to |(u, v)| <= :data:`EDGE_REACH` a: lenslet k's table extended beyond its
  window, each sample there the nearest one inside (:func:`lftransfer.lightfield.window.extend_beyond_window`).
  Steep light from a real surface is read at the nearest direction the lenslet saw it from, which is right for
  diffuse real surfaces whose radiance changes slowly with direction (the point the edge direction sees lies
  beside the one the steep direction meets). Further out the guess overshoots: the real objects end, and at
  grazing angles the synthetic ones see past them. Given the real scene's depth, each steep sample is kept only
  where the steep ray, followed to the depth of the edge sample it reads, still meets a surface.

All lenslets are summed at every shading point (not one picked at random), inside one Dr.Jit loop over the
lenslets that carry light. Shapes of inputs are written as (N,) for N shading points.

For the fast path's glossy lobes (:mod:`lftransfer.render.fast`) the light field light also answers what
arrives along a given direction (:meth:`LightFieldLight.incident`, the area lenslets read where the ray meets
the array plane, through :func:`plane_lookup`) and sums its lenslets with occlusion from a cache instead of
shadow rays (:meth:`LightFieldLight.reflect`); ``illuminate`` takes a BSDF context (only some lobes) and a
weighted irradiance (:data:`Irradiance`) for the same purpose.

The package, one job a module: :mod:`~lftransfer.render.lights.sources` (the point light, the emitting objects and
the weight every light gives a direction), :mod:`~lftransfer.render.lights.environment` (an environment map: a
light probe's or the simulated room's, the lens array blocking it),
:mod:`~lftransfer.render.lights.lightfield_light` (the light field
light and its lighting models), :mod:`~lftransfer.render.lights.sampling` (how it reads the light field:
aperture points, the linear blend, the table beyond the window, the array plane's raster) and
:mod:`~lftransfer.render.lights.jit` (Dr.Jit arrays from NumPy and back).
"""

from __future__ import annotations

from lftransfer.choices import LIGHTING_MODELS, RECONSTRUCTIONS, WINDOWS, LightingModel, Reconstruction, Window
from lftransfer.render.lights.environment import EnvironmentLight
from lftransfer.render.lights.jit import jit_array, jit_rays, to_numpy
from lftransfer.render.lights.lightfield_light import SAMPLING_POOL, Incident, LightFieldLight
from lftransfer.render.lights.sampling import (EDGE_REACH, PLANE_CELLS_PER_PITCH, PlaneLookup, extended_table,
                                               plane_lookup)
from lftransfer.render.lights.sources import EmitterLight, Irradiance, PointLight

__all__ = [
    "EDGE_REACH", "LIGHTING_MODELS", "PLANE_CELLS_PER_PITCH", "RECONSTRUCTIONS", "SAMPLING_POOL", "WINDOWS",
    "EmitterLight", "EnvironmentLight", "Incident", "Irradiance", "LightFieldLight", "LightingModel", "PlaneLookup",
    "PointLight",
    "Reconstruction", "Window", "extended_table", "jit_array", "jit_rays", "plane_lookup", "to_numpy",
]
