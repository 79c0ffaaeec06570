"""The exact path: path tracing of one half-space, every light summed at every hit (:class:`HalfSpaceRenderer`).

The same class renders the synthetic scene for the pipeline and, inside the simulated rig, the real one.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.choices import DEFAULT_SPP
from lftransfer.render.base import RayRenderer
from lftransfer.render.integrator import Light, trace
from lftransfer.render.shapes import scene_dict

__all__ = ["HalfSpaceRenderer"]


class HalfSpaceRenderer(RayRenderer):
    """Renders the objects of one half-space lit by a list of lights by path tracing (the exact path: every light
    sampled at every hit, :func:`~lftransfer.render.integrator.trace`).

    Args:
        objects: scene objects (``lftransfer.scenes.ObjectConfig``).
        extra_shapes: additional Mitsuba shape dicts (e.g. the simulated rig's absorbing lens array).
        max_depth: surface interactions per path (1 = direct light only; more adds interreflections).
        windows: several interfaces' arrays, where paths between objects are cut
            (:class:`~lftransfer.render.windows.Windows`); None: one interface.

    Example:
        >>> r = HalfSpaceRenderer(scene.synthetic)                                        # doctest: +SKIP
        >>> lf = r.render_lightfield(array, [PointLight(p, I)], U=32, V=32, model="area")  # doctest: +SKIP
    """

    kind = "exact"

    def __init__(self, objects: Sequence, *, extra_shapes: dict | None = None, max_depth: int = 3,
                 windows=None) -> None:
        mi = mitsuba()
        self.objects = list(objects)
        self.max_depth = int(max_depth)
        self.windows = windows
        self._extra_shapes = extra_shapes
        self.scene = mi.load_dict(scene_dict(self.objects, extra=extra_shapes), parallel=False, optimize=False)

    def update(self, objects: Sequence) -> bool:
        """Move to new poses of the same objects (an animation frame); the scene is rebuilt only when some
        object's pose or geometry changed.

        Args:
            objects: the objects, posed (``ObjectConfig.at(t)``), in the same order as before.

        Returns:
            Whether anything changed.
        """
        objects = list(objects)
        if [o.model_dump() for o in objects] == [o.model_dump() for o in self.objects]:
            return False
        mi = mitsuba()
        extra = getattr(self, "_extra_shapes", None)
        self.objects = objects
        self.scene = mi.load_dict(scene_dict(self.objects, extra=extra), parallel=False, optimize=False)
        return True

    def render_rays(self, origins: np.ndarray, directions: np.ndarray, lights: Sequence[Light], *,
                    seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Radiance (N, 3), hit mask (N,) and distance (N,) for arbitrary rays (see :func:`trace`)."""
        return trace(self.scene, origins, directions, lights, max_depth=self.max_depth, seed=seed,
                     windows=self.windows)

    def render_view_adjoint(self, sensor, width: int, height: int, light, weights: np.ndarray, *,
                            spp: int = DEFAULT_SPP, seed: int = 0) -> None:
        """The transpose of :meth:`render_view`'s radiance as a linear map of one light's table (a light field
        light, :meth:`~lftransfer.render.lights.LightFieldLight.illuminate_adjoint`): adds A^T ``weights`` to the
        light's gradient table, for the same rays, paths and samples (the same ``spp`` and ``seed``).

        Args:
            sensor, width, height, spp, seed: as in :meth:`render_view`.
            light: the light whose table the view is linear in (the only light of the forward render).
            weights: (H, W, 3) float, d loss / d (pixel radiance).
        """
        from lftransfer.render.camera import view_rays
        from lftransfer.render.integrator import trace_adjoint

        weights = np.asarray(weights, np.float32)
        if weights.shape != (height, width, 3):
            raise ValueError(f"weights have shape {weights.shape}, expected {(height, width, 3)}")
        o, d = self._rays(("view", id(sensor), width, height, spp, seed),
                          lambda: view_rays(sensor, width, height, spp, seed), keep=sensor)
        per_ray = np.repeat(weights.reshape(-1, 3), spp, axis=0) * np.float32(1.0 / spp)   # a pixel: its rays' mean
        trace_adjoint(self.scene, o, d, light, per_ray, max_depth=self.max_depth, seed=seed)

