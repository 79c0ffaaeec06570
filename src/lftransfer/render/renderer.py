"""Rendering one half-space: its outgoing light field (virtual lenslet cameras) and the view camera image.

The same class renders the synthetic scene for the pipeline and, inside the simulated rig, the real one.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Literal, Sequence

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.choices import DEFAULT_LIGHTING_MODEL, DEFAULT_SPP, LightingModel
from lftransfer.lightfield import LightField
from lftransfer.optics import LensArray
from lftransfer.render.integrator import Light, trace
from lftransfer.render.shapes import scene_dict


APERTURE_POOL = 1024


def aperture_offsets(array: LensArray, groups: int, spp: int, seed: int = 0) -> np.ndarray:
    """Stratified aperture points for many independent integrals over a lenslet aperture.

    Each group (a pixel or a light field sample) takes ``spp`` consecutive points of a long low-discrepancy
    sequence over the aperture, from a random start: well spread within a group, different between groups,
    so that no fixed pattern of aperture points shows up in the images.

    Args:
        array: the lens array (its aperture shape).
        groups: number of integrals G.
        spp: points per integral S.
        seed: random seed.

    Returns:
        (G, S, 2) float32 offsets from the lenslet centre, metres.
    """
    pool = array.sample_aperture(APERTURE_POOL, seed=seed).astype(np.float32)
    start = np.random.default_rng(seed).integers(0, APERTURE_POOL, groups)
    return pool[(start[:, None] + np.arange(spp)[None, :]) % APERTURE_POOL]


@dataclass
class ViewImage:
    """A view camera render.

    Attributes:
        rgb: (H, W, 3) float32 radiance, W m^-2 sr^-1.
        alpha: (H, W) float32 coverage in [0, 1] (fraction of the pixel's rays that hit an object).
        depth: (H, W) float32 mean hit distance in metres over covered rays, inf where uncovered.
    """

    rgb: np.ndarray
    alpha: np.ndarray
    depth: np.ndarray


@lru_cache(maxsize=16)
def _sum_weights(spp: int, width: int) -> np.ndarray:
    """(spp * width, width) float32 of ones: a row of ``spp`` samples of ``width`` values each, times it, is their
    sum."""
    w = np.tile(np.eye(width, dtype=np.float32), (spp, 1))
    w.flags.writeable = False
    return w


def sample_mean(values: np.ndarray, spp: int) -> np.ndarray:
    """The mean of every ``spp`` consecutive rows: (N * spp, ...) -> (N, ...) float32 (samples of one pixel or
    light field entry, stored sample-fastest).

    The sums are one matrix product (N, spp * C) @ (spp * C, C) of ones, then scaled by 1 / spp: summing the
    ``spp`` strided slices took 8 ms for a full-resolution light field's 935,040 rays of 3 channels, the product
    1.1 ms, and numpy's mean over the short middle axis 28 ms (it was half of a full-resolution view render)."""
    values = np.asarray(values, np.float32)
    tail = values.shape[1:]
    width = int(np.prod(tail)) if tail else 1
    total = values.reshape(-1, spp * width) @ _sum_weights(spp, width)
    total *= np.float32(1.0 / spp)
    return total.reshape(-1, *tail)


def lightfield_rays(array: LensArray, U: int, V: int, *, side: Literal["synthetic", "real"] = "synthetic",
                    area: bool = True, spp: int = DEFAULT_SPP, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The primary rays of a light field render: for every lenslet k and grid direction d_ij, ``spp`` rays from
    stratified points of the aperture (:func:`aperture_offsets`; the lenslet centre when not ``area``) along
    -d_ij (``side="synthetic"``: looking into z < 0) or +d_ij (``side="real"``).

    Returns:
        origins (K * V * U * spp, 3) float32 in the array plane and directions (the same shape) float32 unit,
        ordered lenslet, direction (row-major over (V, U)), sample.
    """
    K, N, S = array.K, V * U, spp
    dirs = LightField.zeros(array, U, V).directions().reshape(-1, 3).astype(np.float32)       # (V*U, 3)
    if side == "synthetic":
        dirs = -dirs
    origins = np.zeros((K, N, S, 3), np.float32)
    origins[..., :2] = array.centres.astype(np.float32)[:, None, None, :]
    if area:
        origins[..., :2] += aperture_offsets(array, K * N, S, seed).reshape(K, N, S, 2)
    directions = np.broadcast_to(dirs[None, :, None, :], origins.shape)
    return origins.reshape(-1, 3), np.ascontiguousarray(directions.reshape(-1, 3))


def data_entry_rays(array: LensArray, U: int, V: int, **kwargs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`lightfield_rays` (same keyword arguments) of the entries with data only (:meth:`LightField.mask`: a
    hexagonal lenslet's window leaves out 15 % of the (V, U) grid, whose rays a render need not cast).

    Returns:
        origins, directions (E * spp, 3) float32 of the E entries with data, in :func:`lightfield_rays`' order, and
        entries (K * V * U,) bool: which entries those are.
    """
    entries = np.tile(LightField.zeros(array, U, V).mask().ravel(), array.K)
    origins, directions = lightfield_rays(array, U, V, **kwargs)
    rays = np.repeat(entries, len(origins) // len(entries))            # spp rays per entry, sample-fastest
    return origins[rays], directions[rays], entries


@dataclass
class SampleMeans:
    """Means over groups of ``spp`` consecutive rays (the samples of one pixel or one light field entry).

    Attributes:
        radiance: (G, 3) float32 mean radiance, W m^-2 sr^-1 (rays that miss count as zero).
        coverage: (G,) float32 fraction of the group's rays that hit an object.
        depth: (G,) float32 mean hit distance over the rays that hit, metres; inf where none hit.
    """

    radiance: np.ndarray
    coverage: np.ndarray
    depth: np.ndarray


def mean_depth(distance_sum: np.ndarray, hits: np.ndarray) -> np.ndarray:
    """Mean hit distance (G,) float32 from the sum of hit distances and the hit count (or both over the same number
    of rays: their means); inf where nothing hit."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(hits > 0, distance_sum / np.where(hits > 0, hits, 1), np.inf).astype(np.float32)


class HalfSpaceRenderer:
    """Renders the objects of one half-space lit by a list of lights.

    Args:
        objects: scene objects (``lftransfer.scenes.ObjectConfig``).
        extra_shapes: additional Mitsuba shape dicts (e.g. the simulated rig's absorbing lens array).
        max_depth: surface interactions per path (1 = direct light only; more adds interreflections).

    Example:
        >>> r = HalfSpaceRenderer(scene.synthetic)                                        # doctest: +SKIP
        >>> lf = r.render_lightfield(array, [PointLight(p, I)], U=32, V=32, model="area")  # doctest: +SKIP
    """

    def __init__(self, objects: Sequence, *, extra_shapes: dict | None = None, max_depth: int = 3) -> None:
        mi = mitsuba()
        self.objects = list(objects)
        self.max_depth = int(max_depth)
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

    def _rays(self, key: tuple, make):
        """Primary rays are the same from frame to frame: build them once per key (a small memo). The arrays are
        made read-only, which lets a renderer keep their Dr.Jit copies too (:meth:`jit_rays`)."""
        memo = self.__dict__.setdefault("_ray_memo", {})
        if key not in memo:
            if len(memo) >= 8:
                memo.pop(next(iter(memo)))
            arrays = make()
            for a in arrays:
                a.flags.writeable = False
            memo[key] = arrays
        return memo[key]

    def jit_rays(self, origins: np.ndarray, directions: np.ndarray):
        """``mi.Ray3f`` of (N, 3) origins and directions. Read-only arrays (the memoised primary rays) are
        converted once and kept (a few per renderer): converting 4 million rays column by column costs about
        17 ms per frame at the paper's resolution."""
        from lftransfer.render import lights

        kept = self.__dict__.setdefault("_jit_ray_memo", [])
        constant = not origins.flags.writeable and not directions.flags.writeable
        if constant:
            for o, d, rays in kept:
                if o is origins and d is directions:
                    return rays
        rays = lights.jit_rays(origins, directions)
        if constant:
            if len(kept) >= 4:
                kept.pop(0)
            kept.append((origins, directions, rays))
        return rays

    def render_rays(self, origins: np.ndarray, directions: np.ndarray, lights: Sequence[Light], *,
                    seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Radiance (N, 3), hit mask (N,) and distance (N,) for arbitrary rays (see :func:`trace`)."""
        return trace(self.scene, origins, directions, lights, max_depth=self.max_depth, seed=seed)

    def render_samples(self, origins: np.ndarray, directions: np.ndarray, lights: Sequence[Light], spp: int, *,
                       seed: int = 0) -> SampleMeans:
        """Radiance, coverage and depth averaged over every ``spp`` consecutive rays (a pixel's or a light field
        entry's samples, stored sample-fastest): what the light field and view renders need. Every primary ray of
        those renders goes through here.

        Args:
            origins, directions: (G * spp, 3) rays.
            lights: the lights.
            spp: rays per group.
            seed: Monte Carlo seed.

        Returns:
            :class:`SampleMeans` of G groups.
        """
        radiance, hit, dist = self.render_rays(origins, directions, lights, seed=seed)
        hits = sample_mean(hit.astype(np.float32), spp)
        near = sample_mean(np.where(hit, dist, np.float32(0.0)).astype(np.float32), spp)
        return SampleMeans(radiance=sample_mean(radiance, spp), coverage=hits, depth=mean_depth(near, hits))

    def render_lightfield(self, array: LensArray, lights: Sequence[Light], U: int, V: int, *,
                          side: Literal["synthetic", "real"] = "synthetic",
                          model: LightingModel = DEFAULT_LIGHTING_MODEL,
                          spp: int = DEFAULT_SPP, seed: int = 0) -> LightField:
        """The light field this half-space sends through the array.

        For ``side="synthetic"`` entry [k, j, i] is the radiance arriving at lenslet k travelling along +d_ij
        (a virtual camera at the lenslet looking along -d); for ``side="real"`` the radiance travelling along
        -d_ij (what the LF camera captures). With ``model="area"`` each entry averages ``spp`` stratified
        points of the lenslet's aperture; otherwise a pinhole camera at the lenslet centre.

        Returns:
            LightField (K, V, U, 3) float32, masked samples zero.
        """
        lf = LightField.zeros(array, U, V)

        def entry_rays():               # the entries with data, and their values' places in the flat table
            origins, directions, entries = data_entry_rays(array, U, V, side=side, area=model == "area", spp=spp,
                                                           seed=seed)
            return origins, directions, np.repeat(entries, 3)

        origins, directions, channels = self._rays(("lf", array, U, V, side, model == "area", spp, seed), entry_rays)
        means = self.render_samples(origins, directions, lights, spp, seed=seed)
        lf.data.reshape(-1)[channels] = means.radiance.ravel()
        return lf

    def render_view(self, sensor, width: int, height: int, lights: Sequence[Light], *, spp: int = DEFAULT_SPP,
                    seed: int = 0) -> ViewImage:
        """Render the view camera (``sensor`` from :func:`lftransfer.render.camera.sensor_dict`)."""
        from lftransfer.render.camera import view_rays

        o, d = self._rays(("view", id(sensor), width, height, spp, seed),
                          lambda: view_rays(sensor, width, height, spp, seed))
        means = self.render_samples(o, d, lights, spp, seed=seed)
        return ViewImage(rgb=means.radiance.reshape(height, width, 3), alpha=means.coverage.reshape(height, width),
                         depth=means.depth.reshape(height, width))

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
                          lambda: view_rays(sensor, width, height, spp, seed))
        per_ray = np.repeat(weights.reshape(-1, 3), spp, axis=0) * np.float32(1.0 / spp)   # a pixel: its rays' mean
        trace_adjoint(self.scene, o, d, light, per_ray, max_depth=self.max_depth, seed=seed)

