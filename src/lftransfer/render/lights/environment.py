"""Light from an environment at infinity (an equirectangular HDR map: a light probe's, or the simulated room's).

It lights a half-space by next-event estimation: ``samples`` directions per shading point drawn by Mitsuba's
``envmap`` emitter (importance sampling of the map), each with a shadow ray. Rays that leave the scene see the map
(:meth:`EnvironmentLight.background`), where the light is ``visible``: a lenslet camera sees the room behind the
objects, and so does the real view camera; a synthetic view render, composited over the real view, does not.

The lens array as an occluder (``blocker``): light from the room that reaches a synthetic point through the
array's lenslets is not given directly, since the array carries it, as the captured light field (the room seen
past the real objects, which may hide part of it). The test is exact: the ray from the point along the direction
crosses the plane z = 0 inside the array's rectangle, at a direction a lenslet records (|u|, |v| <= a, u = d_x / d_z,
``window`` = a); steeper directions through the array no lenslet records, so the room's light from there is given
directly (the real objects' shadows at those angles are then missing). Directions are in the renderer's frame (the
lens array's); ``rotation`` turns the map's (world) directions into it.
"""

from __future__ import annotations

import copy

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.render.lights.sources import Irradiance, direction_weight

__all__ = ["EnvironmentLight"]


class EnvironmentLight:
    """An environment map lighting a half-space.

    Args:
        radiance: (H, W, 3) float radiance, W m^-2 sr^-1, equirectangular in Mitsuba's ``envmap`` convention
            (:func:`lftransfer.optics.geometry.env_directions`), in the world frame; H = W / 2.
        rotation: (3, 3) world direction -> the renderer's frame (the lens array's); None: the identity.
        blocker: (xmin, xmax, ymin, ymax) of the lens array in the renderer's frame (its plane z = 0), which
            blocks the room's light (see the module); None: nothing blocks it.
        window: with ``blocker``, only directions with |u|, |v| <= ``window`` are blocked (the lenslets' angular
            half-width a); None: every direction through the rectangle.
        samples: directions per shading point.
        visible: whether rays that leave the scene see the map (:meth:`background`).
        seed: seeds the directions.
    """

    def __init__(self, radiance: np.ndarray, rotation: np.ndarray | None = None, *,
                 blocker: tuple[float, float, float, float] | None = None, window: float | None = None,
                 samples: int = 16, visible: bool = True, seed: int = 0) -> None:
        rgb = np.ascontiguousarray(np.asarray(radiance, np.float32)[..., :3])
        if rgb.ndim != 3 or rgb.shape[1] != 2 * rgb.shape[0] or not np.all(np.isfinite(rgb)) or rgb.min() < 0:
            raise ValueError(f"radiance must be a finite, non-negative (H, 2H, 3) map, got shape {rgb.shape}")
        if samples < 1:
            raise ValueError(f"samples must be >= 1, got {samples}")
        self.radiance = rgb
        self.rotation = np.eye(3) if rotation is None else np.asarray(rotation, float)
        self.blocker = None if blocker is None else tuple(float(v) for v in blocker)
        self.window = None if window is None else float(window)
        self.samples = int(samples)
        self.visible = bool(visible)
        self.seed = int(seed)
        self._emitter = None
        self.illuminates = True           # lights the surfaces (False: only seen, :meth:`seen_only`)

    def hidden(self) -> "EnvironmentLight":
        """The same light, not seen by rays that leave the scene (for a render composited over another)."""
        other = copy.copy(self)
        other.visible = False
        return other

    def seen_only(self) -> "EnvironmentLight":
        """The same map as rays that leave the scene see it, lighting nothing (a render of the room behind the
        objects alone; :func:`~lftransfer.render.integrator.trace` then shades nothing)."""
        other = copy.copy(self)
        other.visible, other.illuminates = True, False
        return other

    @property
    def emitter(self):
        """Mitsuba's ``envmap`` emitter of the map, turned into the renderer's frame (built once)."""
        if self._emitter is None:
            mi = mitsuba()
            m = np.eye(4)
            m[:3, :3] = self.rotation
            self._emitter = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(self.radiance),
                                          "to_world": mi.ScalarTransform4f(m.tolist())})
        return self._emitter

    def _blocked(self, p, d):
        """mi.Bool (N,): the ray from ``p`` along ``d`` crosses the array's rectangle in the plane z = 0 (within
        the ``window``, where one is set)."""
        mi = mitsuba()
        import drjit as dr

        if self.blocker is None:
            return mi.Bool(False)
        xmin, xmax, ymin, ymax = self.blocker
        dz = dr.select(dr.abs(d.z) > 1e-12, d.z, 1e-12)
        t = -p.z / dz
        x, y = p.x + t * d.x, p.y + t * d.y
        blocked = (t > 0) & (x >= xmin) & (x <= xmax) & (y >= ymin) & (y <= ymax)
        if self.window is not None:
            blocked &= (dr.abs(d.x / dz) <= self.window) & (dr.abs(d.y / dz) <= self.window)
        return blocked

    def radiance_along(self, directions):
        """mi.Color3f (N,) radiance arriving from ``directions`` (mi.Vector3f, the renderer's frame)."""
        mi = mitsuba()
        import drjit as dr

        si = dr.zeros(mi.SurfaceInteraction3f, dr.width(directions))
        si.wi = -directions
        return mi.Color3f(self.emitter.eval(si))

    def background(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(N, 3) float32 radiance seen along rays that leave the scene (zero where the array blocks the ray, or
        where the light is not ``visible``). ``origins``, ``directions``: (N, 3) float, the renderer's frame."""
        n = len(directions)
        if not self.visible or n == 0:
            return np.zeros((n, 3), np.float32)
        import drjit as dr

        from lftransfer.render.lights.jit import jit_rays, to_numpy

        ray = jit_rays(np.asarray(origins), np.asarray(directions))
        return to_numpy(dr.select(self._blocked(ray.o, ray.d), 0.0, self.radiance_along(ray.d)))

    def illuminate(self, scene, si, active, seed: int = 0, irradiance: Irradiance = False, ctx=None):
        """Light from the environment at the points ``si`` (mi.Color3f, (N,)), reflected towards ``-si.wi`` (the
        BSDF components ``ctx`` enables) or, with ``irradiance``, the (weighted) irradiance on the surface with
        normal ``si.n``; ``samples`` importance-sampled directions, each with a shadow ray and the array's test."""
        mi = mitsuba()
        import drjit as dr

        if not self.illuminates:
            return mi.Color3f(0.0)
        n = dr.width(si.p)
        rng = mi.PCG32(n, dr.opaque(mi.UInt64, self.seed * 1000003 + seed + 17), dr.arange(mi.UInt64, n))
        active = mi.Bool(active)
        emitter = self.emitter
        side = int(round(np.sqrt(self.samples)))
        strata = side if side * side == self.samples else 1
        result = mi.Color3f(0.0)
        it = dr.zeros(mi.Interaction3f, n)
        it.p = si.p
        for j in range(self.samples):
            x, y = (j % strata, j // strata) if strata > 1 else (0, 0)
            sample = mi.Point2f((x + rng.next_float32()) / strata, (y + rng.next_float32()) / strata)
            ds, value = emitter.sample_direction(it, sample, active)
            ok = active & (ds.pdf > 0.0) & ~self._blocked(si.p, ds.d)
            ok &= ~scene.ray_test(si.spawn_ray(ds.d), ok)
            f = direction_weight(si, ds.d, ok, irradiance, ctx)
            result += dr.select(ok, f * mi.Color3f(value), 0.0)
        return result / self.samples

    def irradiance_towards(self, normal: np.ndarray) -> np.ndarray:
        """(3,) irradiance on a plane facing ``normal`` (the renderer's frame) from the whole map, no occluders,
        W m^-2 (the cosine-weighted sum over the map's texels)."""
        from lftransfer.optics.geometry import env_directions, env_solid_angles

        h, w = self.radiance.shape[:2]
        d = env_directions(w, h) @ self.rotation.T
        omega = env_solid_angles(w, h)
        n = np.asarray(normal, float) / np.linalg.norm(normal)
        weight = omega * np.clip(d @ n, 0.0, None)
        return (self.radiance * weight[..., None]).sum(axis=(0, 1))
