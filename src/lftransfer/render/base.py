"""What every renderer of a half-space shares: its primary rays (memoised, and kept as Dr.Jit arrays), the means
over a pixel's or a light field entry's samples, and the light field and view renders built on one method,
``render_rays`` (:class:`RayRenderer`).

The exact path (:class:`~lftransfer.render.renderer.HalfSpaceRenderer`, path tracing) and the fast path
(:class:`~lftransfer.render.fast.CachedRenderer`, an irradiance cache) are both a :class:`RayRenderer`; neither
derives from the other.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import lru_cache
from typing import Literal, Sequence

import numpy as np

from lftransfer.choices import DEFAULT_LIGHTING_MODEL, DEFAULT_SPP, LightingModel
from lftransfer.lightfield import LightField
from lftransfer.optics import LensArray
from lftransfer.optics.geometry import rigid_points, rigid_vectors
from lftransfer.render.integrator import Light

__all__ = ["RayRenderer", "SampleMeans", "ViewImage", "aperture_offsets", "data_entry_rays", "lightfield_rays",
           "mean_depth", "sample_mean"]


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


class RayRenderer(ABC):
    """A renderer of the objects of one half-space lit by a list of lights, built on one method: the radiance, hit
    and distance of arbitrary rays (:meth:`render_rays`). The light field and view renders cast their primary rays
    through :meth:`render_samples`, which a renderer may replace by a faster one of the same result.

    Attributes:
        objects: the scene objects, posed (``lftransfer.scenes.ObjectConfig``).
        scene: the Mitsuba scene the rays are cast into.
        max_depth: surface interactions per path (1 = direct light only; more adds interreflections).
        kind: "exact" (path tracing) or "fast" (the irradiance cache): the renderer choice's value it is.
    """

    kind: str
    objects: list
    scene: object
    max_depth: int
    windows = None          # several interfaces' arrays, where paths between objects are cut (render/windows.py)

    @abstractmethod
    def update(self, objects: Sequence) -> bool:
        """Move to new poses of the same objects (an animation frame); whether anything changed."""

    @abstractmethod
    def render_rays(self, origins: np.ndarray, directions: np.ndarray, lights: Sequence[Light], *,
                    seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Radiance (N, 3) float32 W m^-2 sr^-1, hit mask (N,) bool and hit distance (N,) float32 metres (inf
        where a ray misses) of (N, 3) rays."""

    def _rays(self, key: tuple, make, keep=None):
        """Primary rays are the same from frame to frame: build them once per key (a small memo). The arrays are
        made read-only, which lets a renderer keep their Dr.Jit copies too (:meth:`jit_rays`). ``keep``: an object
        whose ``id`` is in the key (a sensor), held by the memo so that no other object takes its ``id`` while the
        entry lives (a sensor made for one render and dropped would otherwise hand its rays to the next)."""
        memo = self.__dict__.setdefault("_ray_memo", {})
        if key not in memo:
            if len(memo) >= 8:
                memo.pop(next(iter(memo)))
            arrays = make()
            for a in arrays:
                a.flags.writeable = False
            memo[key] = (arrays, keep)
        return memo[key][0]

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
                          spp: int = DEFAULT_SPP, seed: int = 0, pose: np.ndarray | None = None) -> LightField:
        """The light field this half-space sends through the array.

        For ``side="synthetic"`` entry [k, j, i] is the radiance arriving at lenslet k travelling along +d_ij
        (a virtual camera at the lenslet looking along -d); for ``side="real"`` the radiance travelling along
        -d_ij (what the LF camera captures). With ``model="area"`` each entry averages ``spp`` stratified
        points of the lenslet's aperture; otherwise a pinhole camera at the lenslet centre. ``pose``: (4, 4) rigid
        transform from the array's frame to this renderer's (one interface of several); None: the same frame.

        Returns:
            LightField (K, V, U, 3) float32, masked samples zero.
        """
        lf = LightField.zeros(array, U, V)

        def entry_rays():               # the entries with data, and their values' places in the flat table
            origins, directions, entries = data_entry_rays(array, U, V, side=side, area=model == "area", spp=spp,
                                                           seed=seed)
            if pose is not None:
                m = np.asarray(pose, np.float64)
                origins = rigid_points(m, origins).astype(np.float32)
                directions = rigid_vectors(m, directions).astype(np.float32)
            return origins, directions, np.repeat(entries, 3)

        placed = None if pose is None else np.asarray(pose, np.float64).tobytes()
        origins, directions, channels = self._rays(("lf", array, U, V, side, model == "area", spp, seed, placed),
                                                   entry_rays)
        means = self.render_samples(origins, directions, lights, spp, seed=seed)
        lf.data.reshape(-1)[channels] = means.radiance.ravel()
        return lf

    def render_view(self, sensor, width: int, height: int, lights: Sequence[Light], *, spp: int = DEFAULT_SPP,
                    seed: int = 0) -> ViewImage:
        """Render the view camera (``sensor`` from :func:`lftransfer.render.camera.sensor_dict`)."""
        from lftransfer.render.camera import view_rays

        o, d = self._rays(("view", id(sensor), width, height, spp, seed),
                          lambda: view_rays(sensor, width, height, spp, seed), keep=sensor)
        means = self.render_samples(o, d, lights, spp, seed=seed)
        return ViewImage(rgb=means.radiance.reshape(height, width, 3), alpha=means.coverage.reshape(height, width),
                         depth=means.depth.reshape(height, width))
