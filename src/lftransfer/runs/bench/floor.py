"""The ray-casting floor of a transfer iteration: the iteration's own rays cast once against the synthetic scene.

Any ray-traced method that renders the synthetic light field and the view the live step renders must at least
intersect those rays with the synthetic objects once. :class:`RayRecorder` catches the rays exactly as the step's
renderer casts them (no copy of the ray generation here); :func:`ray_floor` times one intersection per ray
(Mitsuba's ``ray_intersect_preliminary``: hit distance, primitive and barycentrics, no shading, no lights), with
the rays already on the device. The rays are cast against the scene's own shapes
(:func:`lftransfer.render.shapes.scene_dict`: analytic shapes and the scene's meshes, as the exact path and the
ground truth intersect them) and against the renderer's own geometry (the fast path's fine tessellation, whose
tighter bounding volumes can make it the faster one); the floor is the faster of the two.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.render.shapes import scene_dict

__all__ = ["RayBatch", "RayRecorder", "FloorTiming", "ray_floor"]


@dataclass(frozen=True)
class RayBatch:
    """Rays one render call of the step cast.

    Attributes:
        origins: (N, 3) float32 ray origins, metres, in the lens array's frame.
        directions: (N, 3) float32 unit directions.
    """

    origins: np.ndarray
    directions: np.ndarray

    @property
    def count(self) -> int:
        """N, the number of rays."""
        return int(len(self.origins))


class RayRecorder:
    """Records the rays a renderer casts while it is active: ``with RayRecorder(renderer) as rec: side.render(...)``.

    The renderer's ``render_samples`` (through which every primary ray of a light field or view render goes) is
    wrapped on the instance (the class is untouched) and unwrapped on exit; the rays are kept by reference (the
    renderers build primary rays once and reuse them, so nothing is copied).

    Attributes:
        batches: one :class:`RayBatch` per ``render_samples`` call, in call order (the step renders the light field
            first, then the view).
    """

    def __init__(self, renderer) -> None:
        self.renderer = renderer
        self.batches: list[RayBatch] = []

    def __enter__(self) -> "RayRecorder":
        inner = self.renderer.render_samples

        def recording(origins, directions, lights, spp, **kwargs):
            self.batches.append(RayBatch(np.asarray(origins), np.asarray(directions)))
            return inner(origins, directions, lights, spp, **kwargs)

        self.renderer.render_samples = recording
        return self

    def __exit__(self, *exc) -> None:
        self.renderer.__dict__.pop("render_samples", None)


@dataclass(frozen=True)
class FloorTiming:
    """The floor: each recorded ray intersected once with the synthetic objects, median over repeats.

    Attributes:
        ms: the floor, milliseconds: casting every batch once (sum over batches, median over the repeats) against
            the faster of the two geometries below.
        geometry: which one that was: "scene" (the scene's own shapes) or "renderer" (the renderer's geometry).
        batch_ms: per batch, the median milliseconds against that geometry (same order as the batches).
        rays: per batch, the number of rays.
        scene_geometry_ms: against the scene's own shapes (:func:`~lftransfer.render.shapes.scene_dict`), ms.
        renderer_geometry_ms: against the renderer's own Mitsuba scene (the fast path's fine tessellation, whose
            tighter bounding volumes can make it the faster one), ms; None where it was not given.
        repeats: timed casts (after one warm-up cast that compiles the kernels).
    """

    ms: float
    geometry: str
    batch_ms: tuple[float, ...]
    rays: tuple[int, ...]
    scene_geometry_ms: float
    renderer_geometry_ms: float | None
    repeats: int


def _cast_times(scene, rays: Sequence, repeats: int) -> np.ndarray:
    """Milliseconds of one ``ray_intersect_preliminary`` per batch, per repeat: (repeats, batches)."""
    import drjit as dr

    def cast(ray) -> float:
        start = time.perf_counter()
        pi = scene.ray_intersect_preliminary(ray)
        dr.eval(pi.t, pi.prim_uv, pi.prim_index, pi.shape)
        dr.sync_thread()
        return time.perf_counter() - start

    for ray in rays:               # warm-up: kernels compiled and cached
        cast(ray)
    return 1000.0 * np.asarray([[cast(ray) for ray in rays] for _ in range(repeats)])


def ray_floor(objects: Sequence, batches: Sequence[RayBatch], *, repeats: int = 10,
              renderer_scene=None) -> FloorTiming:
    """Time casting ``batches`` once each against ``objects`` (one intersection per ray, no shading).

    Args:
        objects: the synthetic objects, posed in the frame the rays are in (``ObjectConfig``).
        batches: the rays (from :class:`RayRecorder`).
        repeats: timed casts of every batch (>= 1), after one warm-up.
        renderer_scene: optionally the renderer's own Mitsuba scene, timed with the same rays too; the floor is
            the faster of the two.

    Returns:
        :class:`FloorTiming`.
    """
    import drjit as dr

    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    if not batches:
        raise ValueError("no rays recorded: the step rendered nothing")
    mi = mitsuba()
    rays = []
    for b in batches:
        o, d = np.ascontiguousarray(b.origins, np.float32), np.ascontiguousarray(b.directions, np.float32)
        ray = mi.Ray3f(mi.Point3f(o[:, 0], o[:, 1], o[:, 2]), mi.Vector3f(d[:, 0], d[:, 1], d[:, 2]))
        dr.eval(ray)
        rays.append(ray)
    geometries = {"scene": mi.load_dict(scene_dict(list(objects)), parallel=False, optimize=False)}
    if renderer_scene is not None:
        geometries["renderer"] = renderer_scene
    times = {name: _cast_times(scene, rays, repeats) for name, scene in geometries.items()}   # (repeats, batches)
    totals = {name: float(np.median(t.sum(axis=1))) for name, t in times.items()}
    best = min(totals, key=totals.get)
    return FloorTiming(ms=round(totals[best], 3), geometry=best,
                       batch_ms=tuple(round(float(x), 3) for x in np.median(times[best], axis=0)),
                       rays=tuple(b.count for b in batches), scene_geometry_ms=round(totals["scene"], 3),
                       renderer_geometry_ms=round(totals["renderer"], 3) if "renderer" in totals else None,
                       repeats=int(repeats))
