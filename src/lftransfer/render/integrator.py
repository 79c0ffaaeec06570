"""Wavefront path tracing of ray batches in one half-space, with next-event estimation only.

Every light of this package is a delta or an explicitly sampled light (point light, lenslets, emitting objects,
an environment map), so a path gathers light only through ``light.illuminate`` at each vertex (and sees an
emitter's own radiance only at its first hit, ``light.emitted``); BSDF sampling continues the path for
interreflections inside the half-space. Rays that miss at the first intersection are compacted away before
any shading, since most rays of a lenslet camera see the background: dark, or a ``visible`` environment's
radiance (``light.background``). A perfect mirror (a delta BSDF) therefore reflects no environment here.
"""

from __future__ import annotations

from typing import Protocol, Sequence

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.render.lights import jit_rays, to_numpy


class Light(Protocol):
    """Anything that adds reflected radiance at surface points (see :mod:`lftransfer.render.lights`); a light
    that is also seen directly (emitting objects) has ``emitted(scene, si, active)`` too."""

    def illuminate(self, scene, si, active, seed: int = 0): ...


def trace(scene, origins: np.ndarray, directions: np.ndarray, lights: Sequence[Light], *,
          max_depth: int = 3, seed: int = 0, windows=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Radiance arriving at ray origins from along the rays.

    Args:
        scene: a loaded Mitsuba scene (one half-space).
        origins: (N, 3) float ray origins, metres.
        directions: (N, 3) float unit directions.
        lights: lights to gather at every path vertex.
        max_depth: surface interactions per path (1 = direct light only).
        seed: random seed (BSDF sampling).
        windows: several interfaces' arrays (:class:`~lftransfer.render.windows.Windows`): a path is cut where a
            later ray crosses one; None: nothing cut.

    Returns:
        radiance (N, 3) float32 W m^-2 sr^-1, hit (N,) bool (first ray hit a surface), distance (N,) float32
        (inf where missed).
    """
    n = len(origins)
    radiance = np.zeros((n, 3), np.float32)
    distance = np.full(n, np.inf, np.float32)
    if n == 0:
        return radiance, np.zeros(0, bool), distance
    o, d, t_np = _first_hits(scene, origins, directions)
    hit = np.isfinite(t_np)
    idx = np.flatnonzero(hit)
    distance[idx] = t_np[idx]
    seen = [light for light in lights if getattr(light, "visible", False)]
    if seen and len(idx) < n:        # rays that leave the scene see a visible environment
        miss = np.flatnonzero(~hit)
        for light in seen:
            radiance[miss] += light.background(o[miss], d[miss])
    if len(idx) == 0 or not any(getattr(light, "illuminates", True) for light in lights):
        return radiance, hit, distance      # nothing hit, or nothing lights what was hit (e.g. a render of depths)
    radiance[idx] = shade(scene, o[idx], d[idx], lights, max_depth=max_depth, seed=seed, windows=windows)
    return radiance, hit, distance


def _first_hits(scene, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(origins, directions) as contiguous float32 and (N,) the distance to each ray's first hit (inf: none)."""
    o = np.ascontiguousarray(origins, dtype=np.float32)
    d = np.ascontiguousarray(directions, dtype=np.float32)
    return o, d, np.array(scene.ray_intersect_preliminary(jit_rays(o, d)).t)


def trace_adjoint(scene, origins: np.ndarray, directions: np.ndarray, light, weights: np.ndarray, *,
                  max_depth: int = 3, seed: int = 0) -> None:
    """The transpose of :func:`trace`'s radiance as a linear map of one light's table: the rays that hit, as
    :func:`trace` finds them, through :func:`shade_adjoint`. ``weights``: (N, 3) per ray."""
    o, d, t = _first_hits(scene, origins, directions)
    idx = np.flatnonzero(np.isfinite(t))
    if len(idx):
        shade_adjoint(scene, o[idx], d[idx], light, np.asarray(weights, np.float32)[idx], max_depth=max_depth,
                      seed=seed)


def _vertices(scene, origins: np.ndarray, directions: np.ndarray, *, max_depth: int, seed: int, windows=None):
    """The path vertices of :func:`shade`: yields (depth, si, active, throughput) for depth 0 .. max_depth - 1.
    The paths depend on the scene and the seed only, never on the lights, so :func:`shade` and
    :func:`shade_adjoint` walk the same ones. With ``windows``, a path ends where a ray after the first crosses an
    array (:mod:`lftransfer.render.windows`)."""
    mi = mitsuba()
    import drjit as dr

    n = len(origins)
    ray = jit_rays(origins, directions)
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(dr.opaque(mi.UInt32, seed), n)
    ctx = mi.BSDFContext()
    throughput = mi.Color3f(1.0)
    active = mi.Bool(True)
    for depth in range(max_depth):
        si = scene.ray_intersect(ray, active)
        active &= si.is_valid()
        if windows is not None and depth > 0:
            active &= ~windows.crossed_jit(ray, si.t)
        yield depth, si, active, throughput
        if depth + 1 == max_depth:
            break
        bs, weight = si.bsdf().sample(ctx, si, sampler.next_1d(active), sampler.next_2d(active), active)
        throughput *= weight
        active &= dr.any(weight != 0.0)
        ray = si.spawn_ray(si.to_world(bs.wo))
        dr.eval(throughput, ray, active)
        sampler.schedule_state()
        if not dr.any(active):
            break


def shade(scene, origins: np.ndarray, directions: np.ndarray, lights: Sequence[Light], *,
          max_depth: int = 3, seed: int = 0, windows=None) -> np.ndarray:
    """Path-traced radiance for rays that are known to hit (no compaction). Shapes as in :func:`trace`."""
    mi = mitsuba()
    import drjit as dr

    result = mi.Color3f(0.0)
    for depth, si, active, throughput in _vertices(scene, origins, directions, max_depth=max_depth, seed=seed,
                                                   windows=windows):
        if depth == 0:     # emitters seen directly; later vertices gather them by next-event estimation
            for light in lights:
                if hasattr(light, "emitted"):
                    result += light.emitted(scene, si, active)
        for light in lights:
            result += throughput * light.illuminate(scene, si, active, seed=seed * 16 + depth)
        dr.eval(result)
    return to_numpy(result)


def shade_adjoint(scene, origins: np.ndarray, directions: np.ndarray, light, weights: np.ndarray, *,
                  max_depth: int = 3, seed: int = 0) -> None:
    """The transpose of :func:`shade` for one light that is linear in a table (a light field light's radiance
    table): adds A^T w to the light's gradient table (``light.illuminate_adjoint``), where A maps the table to
    the rays' radiance with these paths and samples. So <w, shade(table)> = <A^T w, table> exactly, for the same
    seed: the adjoint of the estimator, not of the integral it estimates.

    Args:
        scene, origins, directions, max_depth, seed: as in :func:`shade` (rays that hit).
        light: a light with ``illuminate_adjoint(scene, si, active, weight, seed)``.
        weights: (N, 3) float, w per ray and channel (e.g. d loss / d radiance).
    """
    mi = mitsuba()
    from lftransfer.render.lights import jit_array

    w = np.ascontiguousarray(weights, dtype=np.float32)
    wj = mi.Color3f(*(jit_array(mi.Float, w[:, c]) for c in range(3)))
    for depth, si, active, throughput in _vertices(scene, origins, directions, max_depth=max_depth, seed=seed):
        light.illuminate_adjoint(scene, si, active, throughput * wj, seed=seed * 16 + depth)
