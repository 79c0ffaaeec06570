"""The point light and the emitting objects (next-event estimation with shadow rays), and the weight every light
gives a direction at a shading point (:data:`Irradiance`: BSDF-weighted radiance, irradiance or a weighted
irradiance). Shapes of inputs are written as (N,) for N shading points."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Union

import numpy as np

from lftransfer.backend import mitsuba

#: What ``illuminate`` returns: False, the radiance reflected towards ``-si.wi`` (BSDF-weighted); True, the
#: irradiance on the surface with normal ``si.n`` (each direction weighted by its cosine), W m^-2; a function
#: ``weight(cosine) -> mi.Float`` (per shading point, (N,)), each direction weighted by ``weight(cosine)``
#: instead (the cache of the fast path weights by the cosine times a BSDF's diffuse transmittance).
Irradiance = Union[bool, Callable]


@dataclass
class PointLight:
    """An isotropic point light.

    Args:
        position: (3,) metres.
        intensity: (3,) radiant intensity per channel, W/sr.
    """

    position: np.ndarray
    intensity: np.ndarray

    def illuminate(self, scene, si, active, seed: int = 0, irradiance: Irradiance = False, ctx=None):
        """Light from this light at the points ``si`` (mi.Color3f, (N,)).

        Returns the radiance reflected towards ``-si.wi`` (BSDF-weighted, the BSDF components that ``ctx``
        enables, all by default), or with ``irradiance=True`` the irradiance on the surface with normal ``si.n``
        (W m^-2), for caches of diffuse shading (or, with a weight function, the weighted irradiance: see
        :data:`Irradiance`).
        """
        mi = mitsuba()
        import drjit as dr

        p = mi.Point3f(*[float(c) for c in self.position])
        w = p - si.p
        r2 = dr.squared_norm(w)
        wn = w * dr.rsqrt(r2)
        visible = active & ~scene.ray_test(si.spawn_ray_to(p), active)
        f = direction_weight(si, wn, visible, irradiance, ctx)
        intensity = mi.Color3f(*[float(c) for c in self.intensity])
        return dr.select(visible, f * intensity / r2, 0.0)


class EmitterLight:
    """The emitting objects of a half-space (an ``emitter`` material, e.g. the sun of the paper's Fig. 5).

    They light the other objects by next-event estimation: ``samples`` directions per shading point drawn by
    Mitsuba's emitter sampling of the scene the renderer traces (solid-angle sampling of the visible cap for
    spheres), stratified on a sqrt(samples) x sqrt(samples) grid of the sample square when ``samples`` is a
    square (a sun half hidden behind the horizon of the point it lights is then sampled along its edge, not at
    random), with shadow rays; a ray that meets an emitter sees its radiance (:meth:`emitted`). Give this light
    to a render only where the emitters' own light belongs (the direct frame), never with a captured light
    field that already carries it back.

    Args:
        samples: emitter samples per shading point.
        seed: seeds the samples (each shading point and call draws its own).
        windows: several interfaces' arrays (:class:`~lftransfer.render.windows.Windows`): an emitter's light that
            crosses one on its way is left to the rig, which carries it through the real side; None: one interface.
    """

    def __init__(self, samples: int = 16, seed: int = 0, windows=None) -> None:
        if samples < 1:
            raise ValueError(f"samples must be >= 1, got {samples}")
        self.samples = int(samples)
        self.seed = int(seed)
        self.windows = windows

    def emitted(self, scene, si, active):
        """Radiance the hit emitters send back along the rays (mi.Color3f, (N,)); zero where no emitter."""
        mi = mitsuba()
        import drjit as dr

        active = mi.Bool(active) & si.is_valid()
        return dr.select(active, si.emitter(scene, active).eval(si, active), 0.0)

    def illuminate(self, scene, si, active, seed: int = 0, irradiance: Irradiance = False, ctx=None):
        """Light from the scene's emitters at the points ``si`` (mi.Color3f, (N,)), reflected towards ``-si.wi``
        (the BSDF components ``ctx`` enables) or, with ``irradiance``, the (weighted) irradiance on the surface
        with normal ``si.n``."""
        mi = mitsuba()
        import drjit as dr

        result = mi.Color3f(0.0)
        if len(scene.emitters()) == 0:
            return result
        n = dr.width(si.p)
        rng = mi.PCG32(n, dr.opaque(mi.UInt64, self.seed * 1000003 + seed), dr.arange(mi.UInt64, n))
        active = mi.Bool(active)
        side = int(round(np.sqrt(self.samples)))
        strata = side if side * side == self.samples else 1
        for j in range(self.samples):
            x, y = (j % strata, j // strata) if strata > 1 else (0, 0)
            sample = mi.Point2f((x + rng.next_float32()) / strata, (y + rng.next_float32()) / strata)
            ds, value = scene.sample_emitter_direction(si, sample, True, active)
            ok = active & (ds.pdf > 0.0)
            if self.windows is not None:
                ok &= ~self.windows.crossed_jit(mi.Ray3f(si.p, ds.d), ds.dist)
            f = direction_weight(si, ds.d, ok, irradiance, ctx)
            result += dr.select(ok, f * value, 0.0)
        return result / self.samples


def direction_weight(si, wn, active, irradiance: Irradiance, ctx=None):
    """BSDF value times cosine for direction ``wn`` (world, towards the light; the components ``ctx`` enables),
    or the plain cosine (``irradiance=True``), or ``irradiance(cosine)`` (a weight function)."""
    mi = mitsuba()
    import drjit as dr

    if callable(irradiance):
        return mi.Color3f(irradiance(dr.maximum(dr.dot(si.n, wn), 0.0)))
    if irradiance:
        return mi.Color3f(dr.maximum(dr.dot(si.n, wn), 0.0))
    return si.bsdf().eval(ctx if ctx is not None else mi.BSDFContext(), si, si.to_local(wn), active)
